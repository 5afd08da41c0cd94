"""Assertions with unit-bearing tolerances, for poses, rotations and twists.

Each raises ``AssertionError`` naming the worst element, its index and the tolerance.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from roft_sim.geometry.so3 import quat_angle, quat_from_matrix

__all__ = ["assert_quat_close", "assert_rotation_close", "assert_pose_close", "assert_twist_close"]


def _fail_worst(err: np.ndarray, tol: float, what: str, unit: str) -> None:
    err = np.atleast_1d(err)
    if err.size and not np.all(err <= tol):
        bad = np.where(np.isnan(err), np.inf, err)
        k = np.unravel_index(int(np.argmax(bad)), err.shape)
        raise AssertionError(
            f"{what} error {err[k]:.3e} {unit} > {tol:.1e} {unit} at index "
            f"{tuple(int(i) for i in k)}"
            f" ({int(np.sum(~(err <= tol)))} of {err.size} elements out of tolerance)"
        )


def assert_quat_close(actual: ArrayLike, expected: ArrayLike, *, atol_rad: float = 1e-9) -> None:
    """Quaternions ``(..., 4)`` (w, x, y, z) agree up to sign within ``atol_rad`` of rotation."""
    _fail_worst(quat_angle(actual, expected), atol_rad, "rotation", "rad")


def assert_rotation_close(
    actual: ArrayLike, expected: ArrayLike, *, atol_rad: float = 1e-9
) -> None:
    """Rotation matrices ``(..., 3, 3)`` agree within ``atol_rad`` (geodesic angle)."""
    assert_quat_close(quat_from_matrix(actual), quat_from_matrix(expected), atol_rad=atol_rad)


def assert_pose_close(
    actual: ArrayLike, expected: ArrayLike, *, atol_m: float = 1e-9, atol_rad: float = 1e-9
) -> None:
    """Transforms ``(..., 4, 4)`` agree within ``atol_m`` (translation), ``atol_rad`` (rotation)."""
    a = np.asarray(actual, dtype=np.float64)
    e = np.asarray(expected, dtype=np.float64)
    if a.shape != e.shape:
        raise AssertionError(f"pose shapes differ: {a.shape} vs {e.shape}")
    _fail_worst(np.linalg.norm(a[..., :3, 3] - e[..., :3, 3], axis=-1), atol_m, "translation", "m")
    assert_rotation_close(a[..., :3, :3], e[..., :3, :3], atol_rad=atol_rad)


def assert_twist_close(
    actual: ArrayLike, expected: ArrayLike, *, atol_mps: float = 1e-9, atol_radps: float = 1e-9
) -> None:
    """Twists ``(..., 6)`` ordered (v [m/s], w [rad/s]) agree within the two tolerances."""
    a = np.asarray(actual, dtype=np.float64)
    e = np.asarray(expected, dtype=np.float64)
    if a.shape != e.shape or a.shape[-1:] != (6,):
        raise AssertionError(f"twists must have equal shapes (..., 6): {a.shape} vs {e.shape}")
    _fail_worst(
        np.linalg.norm(a[..., :3] - e[..., :3], axis=-1), atol_mps, "linear velocity", "m/s"
    )
    _fail_worst(
        np.linalg.norm(a[..., 3:] - e[..., 3:], axis=-1), atol_radps, "angular velocity", "rad/s"
    )
