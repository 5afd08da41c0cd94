"""A renderer-free synthetic RGB-D stream: an analytically ray-cast textured box in fast motion.

Every image is exact: the box is intersected with each pixel's ray (slab method), so depth,
visible mask and texture are computed in closed form, and ground-truth flow comes from
:func:`roft_sim.geometry.rigid_flow.rigid_flow`. No MuJoCo, no OpenGL: fast property tests of
trackers run on it at tiny resolutions (e.g. 64x48 to 160x120).

- :class:`AnalyticBox`: the box (size, texture seed) and its camera-independent geometry.
- :class:`AnalyticMotion`: a smooth trajectory with closed-form velocities (sinusoids per axis for
  the position, two sinusoidal rotations about fixed camera axes for the orientation).
- :func:`analytic_box_sequence`: renders N frames into an
  :class:`~roft_sim.datasets.base.InMemorySequence` with ``gt`` flow, ``gt`` masks and a ``gt``
  detector pose set.
- :class:`AnalyticBoxDepthRenderer`: the :class:`~roft_sim.records.DepthRenderer` of the same
  box (for trackers with depth-based outlier rejection, e.g. ROFT).

Conventions: OpenCV camera frame, pixel centres at integer ``(u, v)``, z-depth in metres, static
camera at the world origin. The background is a static textured wall at ``wall_depth_m``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Protocol, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roft_sim.datasets.base import DetectorPoses, InMemorySequence
from roft_sim.errors import ConfigError
from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.geometry.rigid_flow import object_and_static_motions, rigid_flow
from roft_sim.geometry.se3 import transform_from_rt
from roft_sim.geometry.so3 import matrix_from_rotvec
from roft_sim.records import FlowField, ObjectModel, PoseTrack

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]

__all__ = [
    "AnalyticBox",
    "AnalyticMotion",
    "Motion",
    "AnalyticBoxDepthRenderer",
    "analytic_box_sequence",
    "default_intrinsics",
    "raycast_box",
]

_N_WAVES = 12
"""Sinusoids summed per colour channel and face for the texture."""


@dataclass(frozen=True, slots=True, kw_only=True)
class AnalyticBox:
    """A textured box centred on its object-frame origin, faces aligned with the object axes."""

    size_m: tuple[float, float, float] = (0.12, 0.09, 0.06)
    """Edge lengths along the object x, y, z axes [m]."""
    texture_seed: int = 7
    """Seed of the fixed procedural texture (sums of random sinusoids on each face)."""

    def __post_init__(self) -> None:
        if len(self.size_m) != 3 or min(self.size_m) <= 0 or not np.isfinite(self.size_m).all():
            raise ConfigError(f"box size_m must be three positive lengths [m], got {self.size_m}")

    @property
    def half_extents_m(self) -> F64:
        """(3,) half edge lengths [m]."""
        return 0.5 * np.asarray(self.size_m, dtype=np.float64)

    def object_model(self, *, points_per_edge: int = 8) -> ObjectModel:
        """Mesh (8 vertices, 12 triangles) and surface model points in the object frame."""
        h = self.half_extents_m
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        vertices = corners * h
        # Each face as two triangles; vertex index = 4*(sx>0) + 2*(sy>0) + (sz>0).
        quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
        faces = np.array([[a, b, c] for a, b, c, d in quads] + [[a, c, d] for a, b, c, d in quads])
        g = np.linspace(-1.0, 1.0, points_per_edge)
        a, b = np.meshgrid(g, g, indexing="ij")
        pts = []
        for axis in range(3):
            others = [i for i in range(3) if i != axis]
            for sign in (-1.0, 1.0):
                p = np.zeros((a.size, 3))
                p[:, axis] = sign
                p[:, others[0]] = a.ravel()
                p[:, others[1]] = b.ravel()
                pts.append(p)
        model_points = np.unique(np.concatenate(pts), axis=0) * h
        return ObjectModel(
            name="analytic_box",
            vertices_m=vertices,
            faces=faces.astype(np.int64),
            model_points_m=model_points,
        )


class Motion(Protocol):
    """Anything with exact poses and velocities over time (e.g. :class:`AnalyticMotion`)."""

    def track(self, t_s: ArrayLike) -> PoseTrack:
        """Poses and velocities (camera frame) at times ``t_s`` ``(N,)`` [s]."""
        ...


@dataclass(frozen=True, slots=True, kw_only=True)
class AnalyticMotion:
    """A smooth object trajectory in the camera frame with exact velocities.

    Position: ``t(s) = center + amplitude * sin(2 pi frequency s + phase)`` per axis.
    Orientation: ``R(s) = exp(th1(s) a1) exp(th2(s) a2) R0`` with ``thi(s) = Ai sin(2 pi fi s +
    phi_i)`` about fixed unit axes ``a1``, ``a2`` (camera frame), so that the angular velocity in
    the camera frame is ``w = th1' a1 + th2' exp(th1 a1) a2`` exactly.
    """

    center_m: tuple[float, float, float] = (0.0, 0.0, 0.5)
    """Mean object position in the camera frame [m]."""
    amplitude_m: tuple[float, float, float] = (0.06, 0.04, 0.05)
    """Per-axis position amplitude [m]."""
    frequency_hz: tuple[float, float, float] = (0.9, 1.1, 0.7)
    """Per-axis position frequency [Hz]."""
    phase_rad: tuple[float, float, float] = (0.3, 1.2, 2.0)
    """Per-axis position phase [rad]."""
    rotation_axes: tuple[tuple[float, float, float], tuple[float, float, float]] = (
        (0.3, 1.0, 0.2),
        (1.0, -0.2, 0.4),
    )
    """Axes a1, a2 of the two rotations, camera frame (normalised on use)."""
    rotation_amplitude_rad: tuple[float, float] = (0.6, 0.5)
    """Amplitudes A1, A2 [rad]."""
    rotation_frequency_hz: tuple[float, float] = (0.8, 1.0)
    """Frequencies f1, f2 [Hz]."""
    rotation_phase_rad: tuple[float, float] = (0.5, 2.5)
    """Phases phi1, phi2 [rad]."""
    initial_rotvec_rad: tuple[float, float, float] = (0.4, -0.6, 0.3)
    """Rotation vector of R0 [rad]."""

    def scaled(self, speed_scale: float) -> AnalyticMotion:
        """The same path with amplitudes scaled (speeds scale by the same factor)."""
        return dataclasses.replace(
            self,
            amplitude_m=cast(
                tuple[float, float, float], tuple(a * speed_scale for a in self.amplitude_m)
            ),
            rotation_amplitude_rad=cast(
                tuple[float, float], tuple(a * speed_scale for a in self.rotation_amplitude_rad)
            ),
        )

    def track(self, t_s: ArrayLike) -> PoseTrack:
        """Exact poses and velocities (camera frame) at times ``t_s`` ``(N,)`` [s]."""
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        amp = np.asarray(self.amplitude_m)
        om = 2.0 * np.pi * np.asarray(self.frequency_hz)
        arg = t[:, None] * om + np.asarray(self.phase_rad)
        pos = np.asarray(self.center_m) + amp * np.sin(arg)
        vel = amp * om * np.cos(arg)
        axes = np.asarray(self.rotation_axes, dtype=np.float64)
        axes = axes / np.linalg.norm(axes, axis=1, keepdims=True)
        ramp = np.asarray(self.rotation_amplitude_rad)
        rom = 2.0 * np.pi * np.asarray(self.rotation_frequency_hz)
        rarg = t[:, None] * rom + np.asarray(self.rotation_phase_rad)
        th = ramp * np.sin(rarg)  # (N, 2)
        thdot = ramp * rom * np.cos(rarg)
        E1 = matrix_from_rotvec(th[:, :1] * axes[0])
        E2 = matrix_from_rotvec(th[:, 1:] * axes[1])
        R0 = matrix_from_rotvec(np.asarray(self.initial_rotvec_rad))
        R = E1 @ E2 @ R0
        w = thdot[:, :1] * axes[0] + thdot[:, 1:] * np.einsum("nij,j->ni", E1, axes[1])
        return PoseTrack(t_s=t, T_cam_obj=transform_from_rt(R, pos), v_obj_mps=vel, w_radps=w)


def default_intrinsics(width_px: int = 160, height_px: int = 120) -> CameraIntrinsics:
    """Fast-YCB-like pinhole camera (fx = fy = 0.96 width, centred principal point)."""
    f = 0.96 * width_px
    return CameraIntrinsics(
        fx_px=f,
        fy_px=f,
        cx_px=(width_px - 1) / 2.0,
        cy_px=(height_px - 1) / 2.0,
        width_px=width_px,
        height_px=height_px,
    )


def _ray_directions(intrinsics: CameraIntrinsics) -> F64:
    """(H*W, 3) ray directions with unit z, row-major pixel order."""
    v, u = np.mgrid[0 : intrinsics.height_px, 0 : intrinsics.width_px].astype(np.float64)
    d = np.empty(u.shape + (3,))
    d[..., 0] = (u - intrinsics.cx_px) / intrinsics.fx_px
    d[..., 1] = (v - intrinsics.cy_px) / intrinsics.fy_px
    d[..., 2] = 1.0
    return d.reshape(-1, 3)


def raycast_box(
    half_extents_m: ArrayLike, T_cam_obj: ArrayLike, intrinsics: CameraIntrinsics
) -> tuple[F64, NDArray[np.int64], F64]:
    """Intersects every pixel ray with a box (slab method).

    Args:
        half_extents_m: (3,) half edge lengths of the box [m], object frame.
        T_cam_obj: (4, 4) box pose in the camera frame [m].
        intrinsics: the camera.

    Returns:
        depth (H, W) z-depth of the nearest box hit [m], 0 where missed; face (H, W) int64 index
        ``2*axis + (sign > 0)`` of the hit face, -1 where missed; hit (H, W, 3) hit point in the
        object frame [m] (0 where missed).
    """
    h = np.asarray(half_extents_m, dtype=np.float64)
    T = np.asarray(T_cam_obj, dtype=np.float64)
    R, t = T[:3, :3], T[:3, 3]
    shape = intrinsics.shape
    depth = np.zeros(shape)
    face = np.full(shape, -1, dtype=np.int64)
    p_obj = np.zeros(shape + (3,))
    # cast only the rays of the box's projected bounding rectangle (when it is in front)
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * h
    c_cam = corners @ R.T + t
    if (c_cam[:, 2] > 1e-6).all():
        u = intrinsics.fx_px * c_cam[:, 0] / c_cam[:, 2] + intrinsics.cx_px
        v = intrinsics.fy_px * c_cam[:, 1] / c_cam[:, 2] + intrinsics.cy_px
        c0 = max(int(np.floor(u.min())) - 1, 0)
        c1 = min(int(np.ceil(u.max())) + 2, intrinsics.width_px)
        r0 = max(int(np.floor(v.min())) - 1, 0)
        r1 = min(int(np.ceil(v.max())) + 2, intrinsics.height_px)
        if c0 >= c1 or r0 >= r1:
            return depth, face, p_obj
    else:
        r0, r1, c0, c1 = 0, intrinsics.height_px, 0, intrinsics.width_px
    vv, uu = np.mgrid[r0:r1, c0:c1].astype(np.float64)
    d = np.stack(
        [
            ((uu - intrinsics.cx_px) / intrinsics.fx_px).ravel(),
            ((vv - intrinsics.cy_px) / intrinsics.fy_px).ravel(),
            np.ones(uu.size),
        ],
        axis=1,
    )
    o = R.T @ (-t)  # camera origin in the object frame
    e = d @ R  # directions in the object frame: R^T d
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / e
        t1 = (-h - o) * inv
        t2 = (h - o) * inv
    lo = np.fmin(t1, t2)  # fmin/fmax ignore the NaN of rays parallel to a slab at its boundary
    hi = np.fmax(t1, t2)
    # rays parallel to a slab: inside it -> (-inf, inf), outside -> empty
    parallel = e == 0.0
    inside_slab = np.abs(o) <= h
    lo = np.where(parallel, np.where(inside_slab, -np.inf, np.inf), lo)
    hi = np.where(parallel, np.where(inside_slab, np.inf, -np.inf), hi)
    axis = np.argmax(lo, axis=1)
    rows = np.arange(lo.shape[0])
    t_near = lo[rows, axis]
    t_far = hi.min(axis=1)
    hit = (t_near <= t_far) & (t_near > 1e-9)
    sub = (r1 - r0, c1 - c0)
    p_sub = np.where(hit[:, None], o + t_near[:, None] * e, 0.0)
    sign_pos = p_sub[rows, axis] > 0
    depth[r0:r1, c0:c1] = np.where(hit, t_near, 0.0).reshape(sub)
    face[r0:r1, c0:c1] = np.where(hit, 2 * axis + sign_pos, -1).reshape(sub)
    p_obj[r0:r1, c0:c1] = p_sub.reshape(sub + (3,))
    return depth, face, p_obj


def _texture_waves(seed: int) -> tuple[F64, F64, F64]:
    """Per (surface, channel, wave): frequency vectors [cycles/m], phases, amplitudes."""
    rng = np.random.default_rng(seed)
    n_surfaces = 7  # six faces + the wall
    freq_mag = np.exp(rng.uniform(np.log(5.0), np.log(40.0), (n_surfaces, 3, _N_WAVES)))
    angle = rng.uniform(0.0, 2.0 * np.pi, (n_surfaces, 3, _N_WAVES))
    freq = np.stack([freq_mag * np.cos(angle), freq_mag * np.sin(angle)], axis=-1)
    phase = rng.uniform(0.0, 2.0 * np.pi, (n_surfaces, 3, _N_WAVES))
    amp = rng.uniform(0.5, 1.0, (n_surfaces, 3, _N_WAVES)) / np.sqrt(_N_WAVES)
    return freq, phase, amp


def _shade(coords_m: F64, surface: NDArray[np.int64], waves: tuple[F64, F64, F64]) -> F64:
    """RGB in [0, 1], shape (N, 3), from 2-D surface coordinates (N, 2) [m] and surface ids."""
    freq, phase, amp = waves
    f = freq[surface]  # (N, 3, K, 2)
    arg = 2.0 * np.pi * np.einsum("nckd,nd->nck", f, coords_m) + phase[surface]
    base = 0.25 + 0.5 * (surface[:, None] % 3 == np.arange(3)[None, :])  # a tint per surface
    rgb: F64 = np.clip(base + 0.35 * np.sum(amp[surface] * np.sin(arg), axis=-1), 0.0, 1.0)
    return rgb


def _render_wall(
    intrinsics: CameraIntrinsics, wall_depth_m: float, waves: tuple[F64, F64, F64]
) -> F64:
    """(H, W, 3) rgb in [0, 1] of the static wall alone."""
    d = _ray_directions(intrinsics)
    coords = d[:, :2] * wall_depth_m
    rgb = _shade(coords, np.full(coords.shape[0], 6, dtype=np.int64), waves)
    return rgb.reshape(intrinsics.shape + (3,))


def _render_frame(
    box: AnalyticBox,
    T_cam_obj: F64,
    intrinsics: CameraIntrinsics,
    wall_depth_m: float,
    waves: tuple[F64, F64, F64],
    wall_rgb: F64,
) -> tuple[NDArray[np.uint8], F32, NDArray[np.bool_]]:
    depth_obj, face, p_obj = raycast_box(box.half_extents_m, T_cam_obj, intrinsics)
    mask = (depth_obj > 0) & (depth_obj < wall_depth_m)
    rgb = wall_rgb.copy()
    if mask.any():
        f = face[mask]
        axis = f // 2
        p = p_obj[mask]
        # the two in-face coordinates of each hit point
        i0 = np.where(axis == 0, 1, 0)
        i1 = np.where(axis == 2, 1, 2)
        n = np.arange(p.shape[0])
        coords = np.stack([p[n, i0], p[n, i1]], axis=1)
        rgb[mask] = _shade(coords, f, waves)
    depth = np.where(mask, depth_obj, wall_depth_m).astype(np.float32)
    return (np.rint(rgb * 255.0)).astype(np.uint8), depth, mask


@dataclass(frozen=True, slots=True)
class AnalyticBoxDepthRenderer:
    """:class:`~roft_sim.records.DepthRenderer` of an :class:`AnalyticBox` alone (exact z-depth)."""

    box: AnalyticBox = field(default_factory=AnalyticBox)

    def render_depth(self, T_cam_obj: F64, intrinsics: CameraIntrinsics) -> F32:
        """(N, H, W) float32 z-depth [m] of the box at poses ``T_cam_obj`` (N, 4, 4); 0 = miss."""
        T = np.asarray(T_cam_obj, dtype=np.float64)
        if T.ndim != 3 or T.shape[1:] != (4, 4):
            raise ValueError(f"T_cam_obj must have shape (N, 4, 4), got {T.shape}")
        out = np.empty((T.shape[0],) + intrinsics.shape, dtype=np.float32)
        for i in range(T.shape[0]):
            out[i] = raycast_box(self.box.half_extents_m, T[i], intrinsics)[0]
        return out


def analytic_box_sequence(
    *,
    n_frames: int = 30,
    fps: int = 30,
    intrinsics: CameraIntrinsics | None = None,
    box: AnalyticBox | None = None,
    motion: Motion | None = None,
    wall_depth_m: float = 1.2,
    name: str = "analytic_box",
) -> InMemorySequence:
    """Renders the box on its trajectory into an in-memory sequence with exact ground truth.

    Args:
        n_frames: number of camera frames.
        fps: camera rate [Hz]; frame k is at ``k / fps`` s.
        intrinsics: camera; default :func:`default_intrinsics` (160x120).
        box: the object; default :class:`AnalyticBox`.
        motion: the trajectory; default :class:`AnalyticMotion` (peaks near 0.5 m/s and 4 rad/s);
            any :class:`Motion` (e.g. a placed trajectory wrapped by
            :class:`roft_sim.testing.stream_strategies.TrajectoryMotion`).
        wall_depth_m: depth of the static textured background wall [m].
        name: sequence name.

    Returns:
        An :class:`InMemorySequence` with rgb, depth (object and wall), ground-truth poses and
        velocities, ``gt`` visible masks, the ``gt`` flow set (exact rigid flow F_k from k-1 to
        k, occluded or out-of-image pixels invalid; occlusion is the depth test at the nearest
        pixel of frame k, so it is exact up to one pixel at silhouettes: about 0.4 % of object
        pixels near an edge carry the other verdict), a ``gt`` detector pose set (the exact
        poses) and the box's :class:`ObjectModel`.
    """
    if n_frames < 1 or fps < 1:
        raise ConfigError(f"need n_frames >= 1 and fps >= 1, got {n_frames} and {fps}")
    intrinsics = intrinsics or default_intrinsics()
    box = box or AnalyticBox()
    motion = motion or AnalyticMotion()
    gt = motion.track(np.arange(n_frames) / fps)
    if np.any(gt.T_cam_obj[:, 2, 3] - np.linalg.norm(box.half_extents_m) <= 0.05):
        raise ConfigError("the box comes closer than 5 cm to the camera plane; move center_m")
    waves = _texture_waves(box.texture_seed)
    wall_rgb = _render_wall(intrinsics, wall_depth_m, waves)
    rgbs, depths, masks = [], [], []
    for k in range(n_frames):
        rgb, depth, mask = _render_frame(
            box, gt.T_cam_obj[k], intrinsics, wall_depth_m, waves, wall_rgb
        )
        rgbs.append(rgb)
        depths.append(depth)
        masks.append(mask)
    flows: list[FlowField | None] = [None]
    for k in range(1, n_frames):
        body = masks[k - 1].astype(np.int64)  # 0 = static wall, 1 = box
        motions = object_and_static_motions(gt.T_cam_obj[k - 1], gt.T_cam_obj[k])
        flow, valid = rigid_flow(intrinsics, depths[k - 1], body, motions, depth_to_m=depths[k])
        flows.append(FlowField(flow_px=flow, from_k=k - 1, to_k=k, valid=valid))
    return InMemorySequence(
        name=name,
        object_name="analytic_box",
        intrinsics=intrinsics,
        fps=fps,
        rgb_frames=rgbs,
        depth_frames=depths,
        gt=gt,
        gt_masks=masks,
        flows={"gt": flows},
        detector_pose_sets={
            "gt": DetectorPoses(T_cam_obj=gt.T_cam_obj.copy(), valid=np.ones(n_frames, bool))
        },
        model=box.object_model(),
        extra_metadata={
            "generator": "roft_sim.testing.analytic_scene",
            "box": dataclasses.asdict(box),
            "motion": dataclasses.asdict(motion)
            if dataclasses.is_dataclass(motion) and not isinstance(motion, type)
            else repr(motion),
            "wall_depth_m": wall_depth_m,
        },
    )
