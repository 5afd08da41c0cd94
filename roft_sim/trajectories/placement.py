"""Placing a captured motion in front of a static camera.

A captured hand pose ``T_world_hand(t)`` becomes an object pose
``T_cam_obj(t) = T_cam_world @ T_world_hand(t) @ T_hand_obj``:

- ``T_hand_obj`` is the grasp offset (:class:`GraspOffset`);
- ``T_cam_world`` is a constant rigid re-anchoring (:func:`fit_camera_anchor`): the camera
  looks horizontally with the capture's "up" pointing up in the image, along the horizontal
  direction in which the motion spreads least, and it is placed so that as many samples as
  possible keep the object centre inside the :class:`ViewRegion` (the frustum shrunk by a
  margin, between the working distances).

Rigid maps leave speeds unchanged; velocities transform exactly
(:class:`roft_sim.trajectories.rigid_map.RigidlyMappedTrajectory`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roft_sim.errors import ConfigError
from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.geometry.se3 import transform_from_rt
from roft_sim.geometry.so3 import matrix_from_rotvec

F64 = NDArray[np.float64]
Bool = NDArray[np.bool_]

__all__ = [
    "GraspOffset",
    "PlacementConfig",
    "ViewRegion",
    "fit_camera_anchor",
    "camera_rotation_from_up",
    "up_vector",
]


def _check_vector(name: str, value: tuple[float, ...]) -> None:
    if len(value) != 3 or not np.isfinite(value).all():
        raise ConfigError(f"{name} must be three finite numbers, got {value!r}")


@dataclass(frozen=True, slots=True, kw_only=True)
class GraspOffset:
    """Pose of the object in the hand frame, ``T_hand_obj`` (default: the identity)."""

    translation_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Object origin in the hand (tracked body) frame [m]."""
    rotvec_rad: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Rotation of the object frame in the hand frame, as a rotation vector [rad]."""

    def __post_init__(self) -> None:
        _check_vector("grasp translation_m", self.translation_m)
        _check_vector("grasp rotvec_rad", self.rotvec_rad)

    @property
    def T_hand_obj(self) -> F64:
        """(4, 4) the grasp transform [m]."""
        return transform_from_rt(matrix_from_rotvec(np.array(self.rotvec_rad)), self.translation_m)


@dataclass(frozen=True, slots=True, kw_only=True)
class PlacementConfig:
    """Where a captured motion goes in front of the camera."""

    mode: Literal["auto", "fit", "none"] = "auto"
    """``fit``: re-anchor rigidly in front of the camera; ``none``: the file's frame already is
    the camera frame; ``auto``: ``none`` for camera-frame formats (fast-ycb, bop, csv), ``fit``
    for world-frame captures (tum, bvh)."""
    working_distance_m: tuple[float, float] = (0.4, 0.9)
    """Range of the object centre's depth (z) in the camera frame [m]; Fast-YCB: 0.4-0.9."""
    in_view_margin: float = 0.5
    """The object centre keeps at least this fraction of the object radius inside each side
    plane of the camera frustum (0: centre in view; 1: whole bounding sphere in view)."""
    up_axis: Literal["auto", "+x", "-x", "+y", "-y", "+z", "-z"] = "auto"
    """The capture's up direction (shown as image up); ``auto``: +z for TUM, +y for BVH."""
    camera_yaw_deg: float = 0.0
    """Extra rotation of the viewing direction about the up axis [deg], counter-clockwise
    seen from above, on top of the automatic choice."""
    min_in_view_fraction: float = 0.5
    """Fail when fewer samples than this keep the object centre in the view region."""

    def __post_init__(self) -> None:
        near, far = self.working_distance_m
        if not (np.isfinite([near, far]).all() and 0.0 < near < far):
            raise ConfigError(
                f"working_distance_m must be (near, far) with 0 < near < far [m], got "
                f"{self.working_distance_m!r}"
            )
        if not (np.isfinite(self.in_view_margin) and self.in_view_margin >= 0.0):
            raise ConfigError(f"in_view_margin must be >= 0, got {self.in_view_margin}")
        if not np.isfinite(self.camera_yaw_deg):
            raise ConfigError(f"camera_yaw_deg must be finite, got {self.camera_yaw_deg}")
        if not (0.0 <= self.min_in_view_fraction <= 1.0):
            raise ConfigError(
                f"min_in_view_fraction must lie in [0, 1], got {self.min_in_view_fraction}"
            )


@dataclass(frozen=True, slots=True)
class ViewRegion:
    """Convex set of object-centre positions (camera frame) that count as "in view".

    Depth ``z`` in ``[near_m, far_m]``, and the centre at least ``margin_m`` inside each of the
    four side planes of the frustum through the image borders (``u = -0.5``,
    ``u = W - 0.5``, ``v = -0.5``, ``v = H - 0.5``).
    """

    intrinsics: CameraIntrinsics
    near_m: float
    far_m: float
    margin_m: float

    @classmethod
    def from_config(
        cls,
        intrinsics: CameraIntrinsics,
        working_distance_m: tuple[float, float],
        in_view_margin: float,
        object_radius_m: float,
    ) -> ViewRegion:
        """The region for an object of radius ``object_radius_m`` [m].

        Raises:
            ConfigError: the region is empty (margin too wide for the field of view at the far
                distance).
        """
        if not (np.isfinite(object_radius_m) and object_radius_m >= 0):
            raise ConfigError(f"object_radius_m must be >= 0, got {object_radius_m}")
        region = cls(
            intrinsics=intrinsics,
            near_m=float(working_distance_m[0]),
            far_m=float(working_distance_m[1]),
            margin_m=float(in_view_margin * object_radius_m),
        )
        if not region.contains(np.array([region.centre_at(region.far_m)]))[0]:
            raise ConfigError(
                f"no object centre fits in view: an in-view margin of {region.margin_m:.3g} m "
                f"(in_view_margin x object_radius_m) is wider than the field of view at "
                f"{region.far_m} m; lower in_view_margin or increase the working distance"
            )
        return region

    def _slopes(self) -> tuple[float, float, float, float]:
        k = self.intrinsics
        return (
            (-0.5 - k.cx_px) / k.fx_px,
            (k.width_px - 0.5 - k.cx_px) / k.fx_px,
            (-0.5 - k.cy_px) / k.fy_px,
            (k.height_px - 0.5 - k.cy_px) / k.fy_px,
        )

    def centre_at(self, z_m: float) -> F64:
        """(3,) the point at depth ``z_m`` on the ray through the image centre [m]."""
        a_l, a_r, b_t, b_b = self._slopes()
        return np.array([0.5 * (a_l + a_r) * z_m, 0.5 * (b_t + b_b) * z_m, z_m])

    def x_bounds(self, z_m: ArrayLike) -> tuple[F64, F64]:
        """Admissible ``x`` range [m] at depths ``z_m`` (lower, upper; empty if lower > upper)."""
        a_l, a_r, _, _ = self._slopes()
        z = np.asarray(z_m, dtype=np.float64)
        return (
            a_l * z + self.margin_m * np.hypot(1.0, a_l),
            a_r * z - self.margin_m * np.hypot(1.0, a_r),
        )

    def y_bounds(self, z_m: ArrayLike) -> tuple[F64, F64]:
        """Admissible ``y`` range [m] at depths ``z_m``."""
        _, _, b_t, b_b = self._slopes()
        z = np.asarray(z_m, dtype=np.float64)
        return (
            b_t * z + self.margin_m * np.hypot(1.0, b_t),
            b_b * z - self.margin_m * np.hypot(1.0, b_b),
        )

    def contains(self, p_cam: ArrayLike, *, tol_m: float = 1e-12) -> Bool:
        """(N,) True where the points ``(N, 3)`` [m] (camera frame) lie in the region."""
        p = np.asarray(p_cam, dtype=np.float64).reshape(-1, 3)
        x, y, z = p[:, 0], p[:, 1], p[:, 2]
        xl, xh = self.x_bounds(z)
        yl, yh = self.y_bounds(z)
        return (
            (z >= self.near_m - tol_m)
            & (z <= self.far_m + tol_m)
            & (x >= xl - tol_m)
            & (x <= xh + tol_m)
            & (y >= yl - tol_m)
            & (y <= yh + tol_m)
        )

    def sample_points(self, count: int, rng: np.random.Generator) -> F64:
        """``(count, 3)`` points drawn uniformly from the region (rejection sampling) [m].

        Raises:
            ValueError: the region is (nearly) empty.
        """
        depths = np.array([self.near_m, self.far_m])
        xl, xh = self.x_bounds(depths)
        yl, yh = self.y_bounds(depths)
        low = [xl.min(), yl.min(), self.near_m]
        high = [max(xh.max(), xl.min()), max(yh.max(), yl.min()), self.far_m]
        out = np.empty((0, 3))
        for _ in range(1000):
            if out.shape[0] >= count:
                return out[:count]
            cand = rng.uniform(low, high, size=(4 * count + 16, 3))
            out = np.concatenate([out, cand[self.contains(cand)]])
        raise ValueError("the view region is empty or too thin to sample; lower the margin")


_AXIS_VECTORS = {
    "+x": (1.0, 0.0, 0.0),
    "-x": (-1.0, 0.0, 0.0),
    "+y": (0.0, 1.0, 0.0),
    "-y": (0.0, -1.0, 0.0),
    "+z": (0.0, 0.0, 1.0),
    "-z": (0.0, 0.0, -1.0),
}


def up_vector(up_axis: str) -> F64:
    """(3,) unit vector of a ``+x``... ``-z`` axis name."""
    return np.array(_AXIS_VECTORS[up_axis])


def camera_rotation_from_up(p_world: ArrayLike, up_world: ArrayLike, yaw_rad: float = 0.0) -> F64:
    """``R_cam_world`` (3, 3) of a level camera looking across a motion.

    The camera's y axis (image down) is ``-up``; its z axis (viewing direction) is horizontal,
    along the horizontal direction in which the positions ``(N, 3)`` [m] spread least (so the
    motion spreads across the image rather than in depth), its sign chosen so that the
    component of largest magnitude is negative (a BVH character facing +z is seen from the
    front), then turned by ``yaw_rad`` counter-clockwise about ``up``.
    """
    up = np.asarray(up_world, dtype=np.float64)
    up = up / np.linalg.norm(up)
    p = np.asarray(p_world, dtype=np.float64).reshape(-1, 3)
    # an orthonormal basis (e1, e2) of the horizontal plane
    helper = np.eye(3)[int(np.argmin(np.abs(up)))]
    e1 = np.cross(up, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(up, e1)
    h = np.column_stack([p @ e1, p @ e2])
    cov = np.cov(h - h.mean(axis=0), rowvar=False) if len(h) > 1 else np.eye(2)
    evals, evecs = np.linalg.eigh(np.atleast_2d(cov))
    f = evecs[0, 0] * e1 + evecs[1, 0] * e2
    if f[int(np.argmax(np.abs(f)))] > 0:
        f = -f
    f = np.cos(yaw_rad) * f + np.sin(yaw_rad) * np.cross(up, f)
    y_c = -up
    z_c = f / np.linalg.norm(f)
    x_c = np.cross(y_c, z_c)
    return np.stack([x_c, y_c, z_c])


def _best_stab(lo: F64, hi: F64) -> tuple[float, int]:
    """A point covered by the most closed intervals ``[lo_i, hi_i]``, and how many cover it.

    Empty intervals (lo > hi) are ignored. Returns ``(nan, 0)`` when all are empty.
    """
    ok = lo <= hi
    if not ok.any():
        return float("nan"), 0
    lo, hi = lo[ok], hi[ok]
    points = np.concatenate([lo, hi])
    delta = np.concatenate([np.ones(lo.size), -np.ones(hi.size)])
    order = np.lexsort((-delta, points))  # by position, openings before closings
    running = np.cumsum(delta[order])
    k = int(np.argmax(running))
    left = points[order[k]]
    right = points[order[k + 1]] if k + 1 < order.size else left
    return 0.5 * (left + right), int(running[k])


def fit_camera_anchor(
    p_world: ArrayLike,
    region: ViewRegion,
    *,
    R_cam_world: ArrayLike | None = None,
    num_depths: int = 41,
) -> tuple[F64, float]:
    """The rigid ``T_cam_world`` that keeps the most positions in ``region``.

    The rotation is given (default identity); the translation is searched: for each of
    ``num_depths`` depth offsets the lateral offsets that keep the most samples in view are
    found exactly (interval stabbing), first along x and then along y, and the best
    combination is kept (ties: the depth offset nearest the middle of the working range).

    Args:
        p_world: (N, 3) object positions [m] in the capture frame.
        region: where the object centre should stay (camera frame).
        R_cam_world: (3, 3) camera orientation (default identity).
        num_depths: depth offsets tried.

    Returns:
        ``T_cam_world`` (4, 4) and the fraction of samples in the region with it.
    """
    p = np.asarray(p_world, dtype=np.float64).reshape(-1, 3)
    R = np.eye(3) if R_cam_world is None else np.asarray(R_cam_world, dtype=np.float64)
    q = p @ R.T
    z_mid = 0.5 * (region.near_m + region.far_m)
    robust_mid = 0.5 * (np.percentile(q[:, 2], 5.0) + np.percentile(q[:, 2], 95.0))
    depth_best, _ = _best_stab(region.near_m - q[:, 2], region.far_m - q[:, 2])
    lo = region.near_m - q[:, 2].max()
    hi = region.far_m - q[:, 2].min()
    # the list of arrays and lists is joined to list[object] by mypy
    candidates: F64 = np.concatenate(
        [np.linspace(min(lo, hi), max(lo, hi), num_depths), [z_mid - robust_mid]]  # type: ignore[arg-type]
        + ([[depth_best]] if np.isfinite(depth_best) else [])
    )
    best: tuple[int, float, F64] | None = None
    for tz in candidates:
        z = q[:, 2] + tz
        zok = (z >= region.near_m) & (z <= region.far_m)
        xl, xh = region.x_bounds(z)
        tx, _ = _best_stab((xl - q[:, 0])[zok], (xh - q[:, 0])[zok])
        if not np.isfinite(tx):
            continue
        xok = zok & (q[:, 0] + tx >= xl) & (q[:, 0] + tx <= xh)
        yl, yh = region.y_bounds(z)
        ty, _ = _best_stab((yl - q[:, 1])[xok], (yh - q[:, 1])[xok])
        if not np.isfinite(ty):
            continue
        t = np.array([tx, ty, tz])
        count = int(region.contains(q + t).sum())
        key = (count, -abs(tz + robust_mid - z_mid))
        if best is None or key > (best[0], -abs(best[1] + robust_mid - z_mid)):
            best = (count, float(tz), t)
    if best is None:
        t = region.centre_at(z_mid) - np.median(q, axis=0)
        return transform_from_rt(R, t), float(region.contains(q + t).mean())
    return transform_from_rt(R, best[2]), best[0] / len(q)
