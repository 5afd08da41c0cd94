"""The MuJoCo scene: configuration, procedural textures, the hand (rigid proxy,
:mod:`roft_sim.scene.hand`, or articulated with a synthesised grasp,
:mod:`roft_sim.scene.articulated_hand`), camera ego-motion (sway or captured), distractor objects,
and the ``MjSpec`` builder (:mod:`roft_sim.scene.builder`; it and the articulated hand import
MuJoCo: select the GL backend before importing them).

Importing this package imports only the configuration dataclasses (no MuJoCo).
"""

from roft_sim.scene.config import (
    BackgroundConfig,
    CameraFileMotionConfig,
    CameraMotionConfig,
    CameraSwayConfig,
    DistractorConfig,
    FingerConfig,
    HandConfig,
    HandMotionConfig,
    ImageFormationConfig,
    LightConfig,
    RenderConfig,
    SceneConfig,
    TableConfig,
)

__all__ = [
    "BackgroundConfig",
    "CameraFileMotionConfig",
    "CameraMotionConfig",
    "CameraSwayConfig",
    "DistractorConfig",
    "FingerConfig",
    "HandConfig",
    "HandMotionConfig",
    "ImageFormationConfig",
    "LightConfig",
    "RenderConfig",
    "SceneConfig",
    "TableConfig",
]
