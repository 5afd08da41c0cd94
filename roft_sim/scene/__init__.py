"""What is in the scene, described without MuJoCo: the configuration dataclasses, procedural
textures, the rigid hand proxy (:mod:`roft_sim.scene.hand`) and camera ego-motion (sway or
captured). Building the ``MjSpec`` model from them, the articulated hand with its synthesised
grasp and posing mocap bodies belong to :mod:`roft_sim.render` (``scene_builder``,
``articulated_hand``, ``mocap``), the one package that imports MuJoCo. Importing this package
imports only the configuration dataclasses.
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
