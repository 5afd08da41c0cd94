"""Offscreen MuJoCo rendering of rgb, depth and segmentation, and exact ground truth.

Public API (imported lazily, so that ``roft_sim.render.gl_backend`` can choose ``MUJOCO_GL``
before anything imports MuJoCo):

- :class:`SceneRenderer`: renders a scenario frame by frame -> :class:`RenderedFrame`.
- :func:`ground_truth_flow`: exact flow between any two rendered frames.
- :class:`MujocoDepthRenderer`: the ``DepthRenderer`` injected into trackers.
- :class:`OffscreenRenderer`: the low-level one-camera renderer.
"""

from __future__ import annotations

import importlib
from typing import Any

from roft_sim.render.gl_backend import prepare_mujoco_gl

prepare_mujoco_gl()  # before any submodule imports MuJoCo

__all__ = [
    "SceneRenderer",
    "SceneState",
    "RenderedFrame",
    "ground_truth_flow",
    "body_motions",
    "MujocoDepthRenderer",
    "OffscreenRenderer",
]

_LAZY = {
    "SceneRenderer": "roft_sim.render.scene_renderer",
    "SceneState": "roft_sim.render.scene_renderer",
    "RenderedFrame": "roft_sim.render.ground_truth",
    "ground_truth_flow": "roft_sim.render.ground_truth",
    "body_motions": "roft_sim.render.ground_truth",
    "MujocoDepthRenderer": "roft_sim.render.depth_renderer",
    "OffscreenRenderer": "roft_sim.render.offscreen",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'roft_sim.render' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
