"""Posing MuJoCo mocap bodies from 4x4 transforms: the one place that writes ``mocap_pos`` and
``mocap_quat`` (MuJoCo's quaternion order is (w, x, y, z), roft_sim's own)."""

from __future__ import annotations

import mujoco
import numpy as np
from numpy.typing import NDArray

from roft_sim.geometry.so3 import quat_from_matrix

__all__ = ["set_mocap_pose"]


def set_mocap_pose(data: mujoco.MjData, mocap_id: int, T_parent_body: NDArray[np.float64]) -> None:
    """Sets mocap body ``mocap_id`` (its index among the mocap bodies, ``model.body_mocapid``) to
    the pose ``T_parent_body``: (4, 4) rigid transform [m] of the body in the world frame (mocap
    bodies are children of the world). Kinematics are not recomputed (call
    ``mujoco.mj_kinematics`` after posing every body)."""
    data.mocap_pos[mocap_id] = T_parent_body[:3, 3]
    data.mocap_quat[mocap_id] = quat_from_matrix(T_parent_body[:3, :3])
