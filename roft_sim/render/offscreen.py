"""Offscreen rendering of one MuJoCo camera: rgb, z-depth and per-geom segmentation.

A thin layer over MuJoCo's OpenGL renderer (``MjrContext``, ``MjvScene``; the OpenGL context is
the thread's shared one, :mod:`roft_sim.render.gl_contexts`)
that, unlike ``mujoco.Renderer``, reads rgb and depth from ONE render pass, converts MuJoCo's
reversed-Z depth buffer to z-depth in metres (0 = nothing) here and nowhere else, and returns
segmentation as geom ids (-1 = background).

The colour pass uses the model's multisampling (``vis.quality.offsamples``) and, if asked, shadows
(which need the model's shadow map, ``vis.quality.shadowsize`` > 0: MuJoCo allocates it in every
context, so the scene builder leaves it out of scenes without shadows, and the segmentation pass's
context never has one).
Depth and segmentation come from MuJoCo's segmentation pass (flat colours, no lighting), which
MuJoCo renders without blending samples, so every pixel's depth belongs to the geom its id names.
That pass is drawn into a second, single-sample framebuffer (a second ``MjrContext`` made with
``offsamples = 0``, no shadow map and 1x1 textures in the same OpenGL context): with
multisampling off, every sample of a pixel holds the pixel centre's value, so the multisampled
buffer and its resolve give the same ids and depth, bit for bit (tested), for about a quarter of
the fill and no resolve (3.2 vs 11-12 ms of CPU per 640x480 pass on llvmpipe). Without
segmentation and without multisampling, depth is read from the colour pass (one pass).

``MUJOCO_GL`` must be set before ``mujoco`` is first imported: call
``roft_sim.render.gl_backend.select_gl_backend(os.environ)`` first (the CLI and tests do).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from roft_sim.errors import ConfigError
from roft_sim.render.gl_backend import context_error
from roft_sim.render.gl_contexts import SharedGlContext, acquire_gl_context, release_gl_context

__all__ = ["OffscreenRenderer", "RenderBuffers", "z_depth_from_depth_buffer"]

Bool = NDArray[np.bool_]
U8 = NDArray[np.uint8]
F32 = NDArray[np.float32]
I32 = NDArray[np.int32]


def z_depth_from_depth_buffer(buffer: F32, near_m: float, far_m: float) -> F32:
    """z-depth [m] from MuJoCo's reversed-Z depth buffer (``readDepthMap = mjDEPTH_ZEROFAR``).

    MuJoCo's projection maps the near plane to 1 and the far plane to 0, so
    ``z = f n / (b (f - n) + n)``. Pixels at the far plane (``b <= 0``: no geometry) become 0.

    Args:
        buffer: (H, W) float32 depth-buffer values in [0, 1], bottom row first as read by OpenGL
            or already flipped (the conversion is per pixel).
        near_m, far_m: the frustum's near and far distances [m] used for the render.

    Returns:
        (H, W) float32 z-depth [m] (distance to the camera plane), 0 where nothing was drawn;
        computed in float32 (relative error below 1e-6), in one new array.
    """
    z = np.multiply(buffer, np.float32(far_m - near_m), dtype=np.float32)
    z += np.float32(near_m)
    np.divide(np.float32(far_m * near_m), z, out=z)
    z[buffer <= 0.0] = 0.0
    return z


@dataclass(frozen=True, slots=True)
class RenderBuffers:
    """What one :meth:`OffscreenRenderer.render` call produced (None where not asked for)."""

    rgb: U8 | None
    """(H, W, 3) uint8 RGB, row 0 at the top."""
    depth_m: F32 | None
    """(H, W) float32 z-depth [m], 0 = nothing drawn."""
    geom_id: I32 | None
    """(H, W) int32 MuJoCo geom id seen at each pixel, -1 = background or non-geom."""


class OffscreenRenderer:
    """Renders a fixed MuJoCo camera of ``model`` offscreen. A context manager; not thread-safe.

    Args:
        model: the compiled model; ``model.vis.global_.offwidth/offheight`` must be at least the
            render size (the scene builder sets them).
        width_px, height_px: image size [px].
        max_geom: capacity of the abstract scene.

    Raises:
        ConfigError: the offscreen buffer of ``model`` is smaller than the render size.
    """

    def __init__(
        self, model: mujoco.MjModel, width_px: int, height_px: int, *, max_geom: int = 2000
    ) -> None:
        self._gl: SharedGlContext | None = None
        self._ctx: mujoco.MjrContext | None = None
        buf_w, buf_h = model.vis.global_.offwidth, model.vis.global_.offheight
        if width_px > buf_w or height_px > buf_h:
            raise ConfigError(
                f"render size {width_px}x{height_px} exceeds the model's offscreen buffer "
                f"{buf_w}x{buf_h}; set spec.visual.global_.offwidth/offheight to at least the "
                "render size when building the scene"
            )
        self._model = model
        self._width, self._height = int(width_px), int(height_px)
        self._flat_ctx: mujoco.MjrContext | None = None
        try:
            # the thread's context of this size, shared with its other renderers (its first
            # MjrContext pays llvmpipe's per-context costs: roft_sim.render.gl_contexts)
            self._gl = acquire_gl_context(self._width, self._height)
            self._ctx = self._make_context(model)
        except (mujoco.FatalError, RuntimeError, AttributeError) as e:
            self.close()
            raise context_error(e) from e
        self._scene = mujoco.MjvScene(model, maxgeom=max_geom)
        self._option = mujoco.MjvOption()
        self._camera = mujoco.MjvCamera()
        self._camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._rect = mujoco.MjrRect(0, 0, self._width, self._height)
        self._rgb_buf = np.empty((self._height, self._width, 3), dtype=np.uint8)
        self._depth_buf = np.empty((self._height, self._width), dtype=np.float32)

    @staticmethod
    def _make_context(model: mujoco.MjModel) -> mujoco.MjrContext:
        """A rendering context of ``model`` in the current OpenGL context, offscreen, depth
        read as reversed Z (``mjDEPTH_ZEROFAR``); multisampled as ``model`` says."""
        ctx = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_50.value)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, ctx)
        ctx.readDepthMap = mujoco.mjtDepthMap.mjDEPTH_ZEROFAR
        return ctx

    def _flat_context(self) -> mujoco.MjrContext:
        """The context of the segmentation pass: the colour pass's when that one is not
        multisampled, else a single-sample one made on first use (module doc)."""
        assert self._ctx is not None
        if self._model.vis.quality.offsamples <= 0:
            return self._ctx
        if self._flat_ctx is None:
            # single-sample, without a shadow map (the pass casts no shadows; MuJoCo allocates a
            # shadowsize x shadowsize depth texture in every context) and without the model's
            # images: the pass draws flat colours and samples no texture, so every texture is
            # uploaded as its first texel (1x1) instead of at full size with mipmaps (a 2k
            # object atlas and two 1k scene textures: 0.07 s and 20-32 MB of peak memory
            # per renderer; the ids and depth are the same, tested)
            model = self._model
            quality = model.vis.quality
            samples, shadow_px = quality.offsamples, quality.shadowsize
            widths, heights = model.tex_width.copy(), model.tex_height.copy()
            quality.offsamples = quality.shadowsize = 0
            model.tex_width[:] = 1
            model.tex_height[:] = 1
            try:
                self._flat_ctx = self._make_context(model)
            except (mujoco.FatalError, RuntimeError, AttributeError) as e:
                raise context_error(e) from e
            finally:
                quality.offsamples, quality.shadowsize = samples, shadow_px
                model.tex_width[:] = widths
                model.tex_height[:] = heights
        return self._flat_ctx

    @property
    def width_px(self) -> int:
        return self._width

    @property
    def height_px(self) -> int:
        return self._height

    @property
    def scene(self) -> mujoco.MjvScene:
        """The abstract scene (after :meth:`update`)."""
        return self._scene

    def update(self, data: mujoco.MjData, camera_id: int) -> None:
        """Copies the geometry of ``data`` (after ``mj_forward``/``mj_kinematics``) into the scene,
        seen from fixed camera ``camera_id``."""
        self._camera.fixedcamid = camera_id
        mujoco.mjv_updateScene(
            self._model,
            data,
            self._option,
            None,
            self._camera,
            mujoco.mjtCatBit.mjCAT_ALL.value,
            self._scene,
        )

    def render(
        self,
        *,
        rgb: bool = True,
        depth: bool = True,
        segmentation: bool = False,
        shadows: bool = False,
    ) -> RenderBuffers:
        """Renders the scene of the last :meth:`update`.

        Args:
            rgb: produce the colour image.
            depth: produce z-depth.
            segmentation: produce geom ids.
            shadows: cast shadows in the colour pass (the model needs a shadow map).

        Raises:
            ConfigError: ``shadows`` with a model whose ``vis.quality.shadowsize`` is 0.
        """
        if self._ctx is None or self._gl is None:
            raise RuntimeError("OffscreenRenderer used after close()")
        if shadows and rgb and self._ctx.shadowSize <= 0:
            raise ConfigError(
                "shadows asked for, but the model has no shadow map (vis.quality.shadowsize = 0); "
                "build the scene with RenderConfig(shadows=True)"
            )
        self._gl.make_current()
        flags = self._scene.flags
        multisampled = self._model.vis.quality.offsamples > 0
        depth_from_colour = depth and not segmentation and not multisampled and rgb
        out_rgb = out_depth = out_geom = None
        if rgb:
            saved = flags.copy()
            flags[mujoco.mjtRndFlag.mjRND_SHADOW] = shadows
            mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, self._ctx)
            try:
                mujoco.mjr_render(self._rect, self._scene, self._ctx)
            finally:
                np.copyto(flags, saved)
            mujoco.mjr_readPixels(
                self._rgb_buf, self._depth_buf if depth_from_colour else None, self._rect, self._ctx
            )
            out_rgb = np.ascontiguousarray(self._rgb_buf[::-1])
            if depth_from_colour:
                out_depth = self._z_depth(self._depth_buf[::-1])
        if (depth and out_depth is None) or segmentation:
            flat = self._draw_flat()
            mujoco.mjr_readPixels(
                self._rgb_buf if segmentation else None,
                self._depth_buf if depth else None,
                self._rect,
                flat,
            )
            if depth:
                out_depth = self._z_depth(self._depth_buf[::-1])
            if segmentation:
                out_geom = self._geom_ids(self._rgb_buf[::-1])
        return RenderBuffers(rgb=out_rgb, depth_m=out_depth, geom_id=out_geom)

    def _draw_flat(self) -> mujoco.MjrContext:
        """Draws MuJoCo's segmentation pass (flat id colours, no lighting or shadows) into the
        single-sample framebuffer and returns its context, to read from."""
        flags = self._scene.flags
        saved = flags.copy()
        flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = True
        flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = True
        flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
        flat = self._flat_context()
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, flat)
        try:
            mujoco.mjr_render(self._rect, self._scene, flat)
        finally:
            np.copyto(flags, saved)
        return flat

    def render_coverage(self, box_px: tuple[int, int, int, int] | None = None) -> Bool:
        """Where anything is drawn: ``render(rgb=False, depth=True).depth_m > 0``, with the
        depth read only inside ``box_px`` (reading is most of the cost of a small object).

        Args:
            box_px: ``(u0, v0, u1, v1)``, columns ``u0 .. u1 - 1`` and rows ``v0 .. v1 - 1``
                [px] that hold everything drawn (the caller's bound); None = the whole image.

        Returns:
            (H, W) bool, False outside ``box_px``.
        """
        if self._ctx is None or self._gl is None:
            raise RuntimeError("OffscreenRenderer used after close()")
        u0, v0, u1, v1 = (0, 0, self._width, self._height) if box_px is None else box_px
        if not (0 <= u0 <= u1 <= self._width and 0 <= v0 <= v1 <= self._height):
            raise ValueError(
                f"box_px {box_px} is not inside the {self._width}x{self._height} image"
            )
        out = np.zeros((self._height, self._width), dtype=bool)
        if u1 == u0 or v1 == v0:
            return out
        self._gl.make_current()
        flat = self._draw_flat()
        buffer = np.empty((v1 - v0, u1 - u0), dtype=np.float32)
        # OpenGL rows count from the bottom; the depth buffer is 0 where nothing was drawn
        rect = mujoco.MjrRect(u0, self._height - v1, u1 - u0, v1 - v0)
        mujoco.mjr_readPixels(None, buffer, rect, flat)
        out[v0:v1, u0:u1] = buffer[::-1] > 0.0
        return out

    def _z_depth(self, buffer: F32) -> F32:
        cam = self._scene.camera[0]
        return z_depth_from_depth_buffer(buffer, float(cam.frustum_near), float(cam.frustum_far))

    def _geom_ids(self, id_colour: U8) -> I32:
        """Geom ids from MuJoCo's id colours (``segid + 1`` packed little-endian in r, g, b).

        With fewer than 255 scene geoms every id fits in the red byte (a pixel whose green or
        blue byte is set would name a segid beyond the scene: none is drawn), so one 8-bit
        lookup does; larger scenes decode all three bytes."""
        n = self._scene.ngeom
        lut = np.full(max(n + 1, 256), -1, dtype=np.int32)
        geom_type = int(mujoco.mjtObj.mjOBJ_GEOM)
        for i in range(n):
            g = self._scene.geoms[i]
            if g.segid >= 0 and g.objtype == geom_type:
                lut[g.segid + 1] = g.objid
        lut[0] = -1
        if n < 255:
            return lut[id_colour[..., 0]]
        code = id_colour.astype(np.int32)
        segid = code[..., 0] | (code[..., 1] << 8) | (code[..., 2] << 16)
        segid = np.where(segid <= n, segid, 0)
        labels: NDArray[np.int32] = lut[segid]
        return labels

    def close(self) -> None:
        """Frees this renderer's OpenGL resources and releases its thread's context, which is
        kept for the thread's next renderer (``roft_sim.render.gl_contexts``; idempotent)."""
        if self._ctx is not None and self._gl is not None:
            self._gl.make_current()
            if self._flat_ctx is not None:
                self._flat_ctx.free()
            self._ctx.free()
        self._ctx = self._flat_ctx = None
        if self._gl is not None:
            release_gl_context(self._gl)
        self._gl = None

    def __enter__(self) -> OffscreenRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        # At interpreter shutdown the GL library may already be gone, and so may module
        # globals such as contextlib: only builtins are safe here.
        try:  # noqa: SIM105
            self.close()
        except Exception:
            pass
