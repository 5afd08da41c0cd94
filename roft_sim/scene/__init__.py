"""The MuJoCo scene: configuration, procedural textures, hand occluder, camera ego-motion, and
the ``MjSpec`` builder (:mod:`roft_sim.scene.builder`, which imports MuJoCo: select the GL backend
before importing it).

Importing this package imports only the configuration dataclasses (no MuJoCo).
"""

from roft_sim.scene.config import (
    BackgroundConfig,
    CameraMotionConfig,
    CameraSwayConfig,
    HandConfig,
    LightConfig,
    RenderConfig,
    SceneConfig,
    TableConfig,
)

__all__ = [
    "BackgroundConfig",
    "CameraMotionConfig",
    "CameraSwayConfig",
    "HandConfig",
    "LightConfig",
    "RenderConfig",
    "SceneConfig",
    "TableConfig",
]
