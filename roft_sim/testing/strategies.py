"""Hypothesis strategies for geometry (more are added for trajectories, faults and streams)."""

from __future__ import annotations

from typing import TypedDict

import numpy as np
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from roft_sim.geometry.se3 import transform_from_pq
from roft_sim.geometry.so3 import as_quat_wxyz

__all__ = [
    "unit_quaternions",
    "rotation_vectors",
    "small_rotation_vectors",
    "translations",
    "transforms",
]


class FiniteFloats(TypedDict):
    """Keyword arguments of ``st.floats`` that exclude NaN and infinities."""

    allow_nan: bool
    allow_infinity: bool


_finite: FiniteFloats = {"allow_nan": False, "allow_infinity": False}


def unit_quaternions() -> st.SearchStrategy[np.ndarray]:
    """Unit quaternions (w, x, y, z), any sign, including near-identity and near-pi rotations."""
    generic = arrays(np.float64, 4, elements=st.floats(-1, 1, **_finite)).filter(
        lambda q: np.linalg.norm(q) > 1e-3
    )
    special = st.sampled_from(
        [
            [1, 0, 0, 0],
            [0, 1, 0, 0],
            [0, 0, 1, 0],
            [0, 0, 0, 1],
            [1e-9, 1, 0, 0],
            [1, 1e-9, 0, 0],
            [-1, 0, 0, 0],
            [0.5, 0.5, 0.5, 0.5],
        ]
    ).map(lambda q: np.array(q, dtype=np.float64))
    return st.one_of(generic, special).map(as_quat_wxyz)


def rotation_vectors(max_angle_rad: float = np.pi) -> st.SearchStrategy[np.ndarray]:
    """Rotation vectors with angle in [0, max_angle_rad] [rad]."""
    return st.tuples(unit_quaternions(), st.floats(0, max_angle_rad, **_finite)).map(
        lambda qa: (
            qa[0][1:] / max(np.linalg.norm(qa[0][1:]), 1e-300) * qa[1]
            if np.linalg.norm(qa[0][1:]) > 1e-9
            else np.array([qa[1], 0.0, 0.0])
        )
    )


def small_rotation_vectors() -> st.SearchStrategy[np.ndarray]:
    """Rotation vectors with angles from 1e-12 to 1e-3 rad (series branches)."""
    return st.tuples(unit_quaternions(), st.floats(-12, -3)).map(
        lambda qe: (
            (
                qe[0][1:] / np.linalg.norm(qe[0][1:])
                if np.linalg.norm(qe[0][1:]) > 1e-6
                else np.array([0.0, 0.0, 1.0])
            )
            * 10.0 ** qe[1]
        )
    )


def translations(max_abs_m: float = 2.0) -> st.SearchStrategy[np.ndarray]:
    """Translations [m] with components in [-max_abs_m, max_abs_m]."""
    return arrays(np.float64, 3, elements=st.floats(-max_abs_m, max_abs_m, **_finite))


def transforms(max_abs_m: float = 2.0) -> st.SearchStrategy[np.ndarray]:
    """Rigid transforms (4, 4)."""
    return st.tuples(translations(max_abs_m), unit_quaternions()).map(
        lambda pq: transform_from_pq(*pq)
    )
