"""MuJoCo implementation of :class:`roft_sim.records.DepthRenderer`: the depth of ONE object, alone.

Trackers (ROFT's outlier rejection) receive an instance and call :meth:`render_depth`; they
never import MuJoCo. One small scene per image size is built on first use (the object mesh, a
camera, nothing else) and kept; other intrinsics of the same size only update the compiled
camera's ``cam_intrinsic`` (no recompilation).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray

from roft_sim.geometry import CameraIntrinsics, as_transform, project_points
from roft_sim.render.camera import mujoco_camera_params
from roft_sim.render.mocap import set_mocap_pose
from roft_sim.render.offscreen import OffscreenRenderer
from roft_sim.render.scene_builder import BuiltScene, build_scene
from roft_sim.scene.config import BackgroundConfig, RenderConfig, SceneConfig, TableConfig

Bool = NDArray[np.bool_]
F32 = NDArray[np.float32]
F64 = NDArray[np.float64]

__all__ = ["MujocoDepthRenderer"]


@dataclass(frozen=True, slots=True)
class _PlainMesh:
    vertices_m: F64
    faces: NDArray[np.int64]


class MujocoDepthRenderer:
    """Renders z-depth images of one object at given poses (no table, background or hand).

    Args:
        obj: an ``ObjectModel`` (``vertices_m``, ``faces``), an ``ObjectAssets`` (``.mesh``) or
            any mesh with ``vertices_m`` (V, 3) [m] and ``faces`` (F, 3) in the object frame.
        znear_m, zfar_m: clipping distances [m].
    """

    def __init__(self, obj: Any, *, znear_m: float = 0.01, zfar_m: float = 20.0) -> None:
        mesh = getattr(obj, "mesh", obj)
        self._mesh = _PlainMesh(
            vertices_m=np.asarray(mesh.vertices_m, dtype=np.float64),
            faces=np.asarray(mesh.faces, dtype=np.int64),
        )
        v = self._mesh.vertices_m
        lo, hi = v.min(axis=0), v.max(axis=0)
        # (8, 3) corners of the mesh's axis-aligned box, object frame [m]
        self._box_corners_m = np.array(
            [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
        )
        self._znear_m = float(znear_m)
        self._render_config = RenderConfig(znear_m=znear_m, zfar_m=zfar_m)
        self._scenes: dict[
            tuple[int, int], tuple[BuiltScene, mujoco.MjData, OffscreenRenderer]
        ] = {}

    def _scene_for(
        self, intrinsics: CameraIntrinsics
    ) -> tuple[BuiltScene, mujoco.MjData, OffscreenRenderer]:
        size = (intrinsics.width_px, intrinsics.height_px)
        if size not in self._scenes:
            built = build_scene(
                intrinsics=intrinsics,
                object_mesh=self._mesh,
                scene=SceneConfig(
                    table=TableConfig(enabled=False),
                    background=BackgroundConfig(enabled=False),
                    lights=(),
                ),
                render=self._render_config,
                rng=np.random.default_rng(0),
            )
            self._scenes[size] = (
                built,
                mujoco.MjData(built.model),
                OffscreenRenderer(built.model, *size),
            )
        built, data, renderer = self._scenes[size]
        params = mujoco_camera_params(intrinsics)
        cam = built.camera_id
        model = built.model
        model.cam_sensorsize[cam] = params.sensor_size_m
        sw, sh = params.sensor_size_m
        model.cam_intrinsic[cam] = [
            params.focal_pixel[0] / size[0] * sw,
            params.focal_pixel[1] / size[1] * sh,
            params.principal_pixel[0] / size[0] * sw,
            params.principal_pixel[1] / size[1] * sh,
        ]
        return built, data, renderer

    @staticmethod
    def _pose(
        built: BuiltScene, data: mujoco.MjData, renderer: OffscreenRenderer, T_cam_obj: F64
    ) -> None:
        """Puts the object at ``T_cam_obj`` (4, 4) [m] in the renderer's scene."""
        set_mocap_pose(data, built.object_mocap, T_cam_obj)
        mujoco.mj_kinematics(built.model, data)
        mujoco.mj_camlight(built.model, data)
        renderer.update(data, built.camera_id)

    def render_depth(self, T_cam_obj: ArrayLike, intrinsics: CameraIntrinsics) -> F32:
        """Depth images of the object alone.

        Args:
            T_cam_obj: (N, 4, 4) (or (4, 4)) object poses in the camera frame [m].
            intrinsics: camera to render with (any resolution and principal point).

        Returns:
            (N, H, W) float32 z-depth [m], 0 where the object is not seen.
        """
        T = as_transform(T_cam_obj)
        if T.ndim == 2:
            T = T[None]
        built, data, renderer = self._scene_for(intrinsics)
        out = np.empty((T.shape[0],) + intrinsics.shape, dtype=np.float32)
        for i, pose in enumerate(T):
            self._pose(built, data, renderer, pose)
            depth = renderer.render(rgb=False, depth=True).depth_m
            assert depth is not None
            out[i] = depth
        return out

    def render_silhouette(self, T_cam_obj: ArrayLike, intrinsics: CameraIntrinsics) -> Bool:
        """The object's silhouette at one pose: ``render_depth(T_cam_obj, intrinsics)[0] > 0``,
        bit for bit, reading only the pixels inside the projection of the mesh's box (plus 2 px)
        when the whole box is beyond the near plane.

        Args:
            T_cam_obj: (4, 4) object pose in the camera frame [m].
            intrinsics: camera to render with.

        Returns:
            (H, W) bool, True where the object is drawn.
        """
        T = as_transform(T_cam_obj)
        built, data, renderer = self._scene_for(intrinsics)
        self._pose(built, data, renderer, T)
        return renderer.render_coverage(self._box_px(T, intrinsics))

    def _box_px(
        self, T_cam_obj: F64, intrinsics: CameraIntrinsics
    ) -> tuple[int, int, int, int] | None:
        """``(u0, v0, u1, v1)`` [px] holding the projection of the mesh's box grown by 2 px and
        clipped to the image, or None when a corner is not beyond the near plane (then the
        projection of the box does not bound the drawing)."""
        p = self._box_corners_m @ T_cam_obj[:3, :3].T + T_cam_obj[:3, 3]
        if not (p[:, 2] > self._znear_m).all():
            return None
        uv = project_points(intrinsics, p)
        w, h = intrinsics.width_px, intrinsics.height_px
        u0 = min(max(int(np.floor(uv[:, 0].min())) - 2, 0), w)
        v0 = min(max(int(np.floor(uv[:, 1].min())) - 2, 0), h)
        u1 = max(min(int(np.ceil(uv[:, 0].max())) + 3, w), u0)
        v1 = max(min(int(np.ceil(uv[:, 1].max())) + 3, h), v0)
        return u0, v0, u1, v1

    def close(self) -> None:
        """Frees every OpenGL context (idempotent)."""
        for _, _, renderer in self._scenes.values():
            renderer.close()
        self._scenes.clear()

    def __enter__(self) -> MujocoDepthRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
