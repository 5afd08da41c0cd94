"""Scenario files: one TOML file describes a whole rendered sequence.

A scenario names the camera (intrinsics, resolution, rate, optional ego-motion), the object
(registry name or mesh file), its trajectory, the scene (table, background, lights, hand
occluder), render options, the seed and the length. Loading is strict
(:mod:`roft_sim.config_files`): unknown keys and bad values raise :class:`ConfigError` naming the
file, the key and the fix. Relative paths are resolved against the scenario file's folder when it
is loaded. Every key, its unit and default: ``docs/scenarios.md``.

Randomness: :meth:`Scenario.seed_sequence` gives each subsystem its own stream derived from
``seed`` and the subsystem's name, so adding a subsystem never changes another one's numbers.
"""

from __future__ import annotations

import dataclasses
import logging
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from roft_sim.config_files import dataclass_from_mapping, load_toml
from roft_sim.errors import ConfigError
from roft_sim.geometry import CameraIntrinsics
from roft_sim.scene.config import CameraMotionConfig, DistractorConfig, RenderConfig, SceneConfig
from roft_sim.sensors.networks import NetworksConfig
from roft_sim.trajectories import (
    CapturedMotionConfig,
    HandMotionConfig,
    TrajectoryConfig,
    resolve_hand_motion,
)

__all__ = ["CameraConfig", "ObjectConfig", "Scenario", "load_scenario", "FAST_YCB_CAMERA_CONFIG"]

_log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True, kw_only=True)
class CameraConfig:
    """The RGB-D camera: pinhole intrinsics (OpenCV convention, pixel centres at integers),
    resolution, frame rate and optional ego-motion."""

    width_px: int
    """Image width [px]."""
    height_px: int
    """Image height [px]."""
    fx_px: float
    """Focal length along u [px]."""
    fy_px: float
    """Focal length along v [px]."""
    cx_px: float
    """Principal point column [px]; need not be the image centre."""
    cy_px: float
    """Principal point row [px]."""
    fps: int = 30
    """Frames per second (an integer; frame k is at ``k / fps`` s)."""
    motion: CameraMotionConfig | None = None
    """Camera ego-motion (``[camera.motion]``, ``kind = "sway" | "file"``); absent = static
    camera at the world origin."""

    def __post_init__(self) -> None:
        if self.fps <= 0:
            raise ConfigError(f"camera.fps must be a positive integer, got {self.fps}")
        self.intrinsics  # noqa: B018 - validates the intrinsics

    @property
    def intrinsics(self) -> CameraIntrinsics:
        """The pinhole intrinsics."""
        return CameraIntrinsics(
            fx_px=self.fx_px,
            fy_px=self.fy_px,
            cx_px=self.cx_px,
            cy_px=self.cy_px,
            width_px=self.width_px,
            height_px=self.height_px,
        )


FAST_YCB_CAMERA_CONFIG = CameraConfig(
    width_px=1280,
    height_px=720,
    fx_px=1229.4285612615463,
    fy_px=1229.4285612615463,
    cx_px=640.0,
    cy_px=360.0,
    fps=30,
)
"""The Fast-YCB camera (``../shared/reference/fast_ycb_format.md``)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class ObjectConfig:
    """The tracked object: a registry name or a mesh file (exactly one)."""

    name: str | None = None
    """Registry name, e.g. ``003_cracker_box`` (real mesh when installed, else the procedural
    stand-in)."""
    mesh: Path | None = None
    """Textured mesh file (``.obj`` with its ``.mtl`` and texture) in the object frame of the
    poses; relative paths resolve against the scenario file's folder."""

    def __post_init__(self) -> None:
        if (self.name is None) == (self.mesh is None):
            raise ConfigError(
                "[object] needs exactly one of name = '<registry name>' or mesh = '<file>', got "
                f"name={self.name!r}, mesh={None if self.mesh is None else str(self.mesh)!r}"
            )

    @property
    def name_or_path(self) -> str | Path:
        """What ``roft_sim.assets.load_object`` takes."""
        return self.mesh if self.mesh is not None else self.name  # type: ignore[return-value]


@dataclass(frozen=True, slots=True, kw_only=True)
class Scenario:
    """A rendered sequence, fully specified (see the module doc and ``docs/scenarios.md``)."""

    name: str
    """Scenario name (used for output folders and reports)."""
    camera: CameraConfig
    """The camera (``[camera]``)."""
    object: ObjectConfig
    """The object (``[object]``)."""
    trajectory: TrajectoryConfig
    """The object's motion (``[trajectory]``, ``kind = "synthetic" | "continuous" | "file" |
    "hand-motion"``; the last is resolved by :func:`load_scenario`), placed in front
    of the camera at rest."""
    scene: SceneConfig = field(default_factory=SceneConfig)
    """Table, background, lights and hand (``[scene]``)."""
    render: RenderConfig = field(default_factory=RenderConfig)
    """Render options (``[render]``)."""
    networks: NetworksConfig = field(default_factory=NetworksConfig)
    """Simulated networks run on every frame when the scenario is generated into a dataset
    (``[networks]``: pose estimator, segmenter, flow sets; defaults reproduce the reference
    Fast-YCB layout). See ``docs/generate.md``."""
    seed: int = 0
    """Seed of every random choice of the scenario (textures, depth noise; the trajectory config
    carries its own)."""
    duration_s: float | None = None
    """Length [s]; give this or ``frames``."""
    frames: int | None = None
    """Number of camera frames; give this or ``duration_s``."""

    def __post_init__(self) -> None:
        if not self.name:
            raise ConfigError("scenario name must be a non-empty string")
        if self.seed < 0:
            raise ConfigError(f"seed must be >= 0, got {self.seed}")
        if (self.duration_s is None) == (self.frames is None):
            raise ConfigError(
                "give exactly one of duration_s = <seconds> or frames = <count>, got "
                f"duration_s={self.duration_s}, frames={self.frames}"
            )
        if self.frames is not None and self.frames < 1:
            raise ConfigError(f"frames must be >= 1, got {self.frames}")
        wall = self.scene.background
        if wall.enabled and wall.distance_m >= self.render.zfar_m:
            raise ConfigError(
                f"scene.background.distance_m = {wall.distance_m} m lies beyond render.zfar_m = "
                f"{self.render.zfar_m} m: the wall would be clipped away (depth 0, no flow); "
                "raise zfar_m, bring the wall closer, or set scene.background.enabled = false"
            )
        if self.duration_s is not None:
            if not (np.isfinite(self.duration_s) and self.duration_s > 0):
                raise ConfigError(f"duration_s must be a positive number, got {self.duration_s}")
            if round(self.duration_s * self.camera.fps) < 1:
                raise ConfigError(
                    f"duration_s = {self.duration_s} s is shorter than one frame at "
                    f"{self.camera.fps} fps"
                )

    @property
    def intrinsics(self) -> CameraIntrinsics:
        """The camera's pinhole intrinsics."""
        return self.camera.intrinsics

    @property
    def fps(self) -> int:
        """Camera frame rate [Hz]."""
        return self.camera.fps

    @property
    def n_frames(self) -> int:
        """Number of camera frames: ``frames``, or ``round(duration_s * fps)``."""
        if self.frames is not None:
            return self.frames
        return int(round(self.duration_s * self.camera.fps))  # type: ignore[operator]

    def frame_time_s(self, k: int) -> float:
        """Time stamp of frame ``k``: ``k / fps`` [s]."""
        return k / self.camera.fps

    def seed_sequence(self, subsystem: str, *index: int) -> np.random.SeedSequence:
        """The random stream of one subsystem (e.g. ``"depth_noise"``, per frame ``k``):
        ``SeedSequence(seed, spawn_key=(crc32(subsystem), *index))``."""
        key = zlib.crc32(subsystem.encode("utf-8"))
        return np.random.SeedSequence(self.seed, spawn_key=(key, *(int(i) for i in index)))

    def rng(self, subsystem: str, *index: int) -> np.random.Generator:
        """A generator on :meth:`seed_sequence`."""
        return np.random.default_rng(self.seed_sequence(subsystem, *index))


def load_scenario(path: str | Path) -> Scenario:
    """Reads a scenario TOML file strictly.

    Relative paths in it (``[object] mesh``, ``[trajectory] path``, ``[camera.motion] path``, the
    distractors' mesh and trajectory files) are resolved here, against the file's folder, and
    stored absolute. A ``kind = "hand-motion"`` trajectory is resolved here too, into the motion
    it stands for (the captured file when present, else the fitted continuous profile; logged),
    so that the scenario, and the metadata of what it generates, say which motion was used.

    Raises:
        ConfigError: missing file, invalid TOML, unknown key, missing key or bad value; the
            message names the file, the key and the fix.
    """
    path = Path(path)
    data = load_toml(path)
    where = f"{path}:"
    try:
        scenario = dataclass_from_mapping(Scenario, data, where=where)
    except ConfigError as e:  # top-level keys would read "file.toml:: ..."
        raise ConfigError(str(e).replace(f"{where}:", where, 1)) from None
    base_dir = path.resolve().parent
    obj = scenario.object
    if obj.mesh is not None and not obj.mesh.is_absolute():
        obj = dataclasses.replace(obj, mesh=base_dir / obj.mesh)
    trajectory: TrajectoryConfig = scenario.trajectory
    if isinstance(trajectory, CapturedMotionConfig) and not trajectory.path.is_absolute():
        trajectory = dataclasses.replace(trajectory, path=base_dir / trajectory.path)
    if isinstance(trajectory, HandMotionConfig):  # captured when present, else fitted
        trajectory, reason = resolve_hand_motion(trajectory.with_base_dir(base_dir))
        _log.info("%s: hand-motion trajectory: %s", path.name, reason)
    camera = scenario.camera
    motion_path = getattr(camera.motion, "path", None)
    if isinstance(motion_path, Path) and not motion_path.is_absolute():
        motion = dataclasses.replace(camera.motion, path=base_dir / motion_path)  # type: ignore[type-var]
        camera = dataclasses.replace(camera, motion=motion)
    distractors = tuple(_resolve_distractor(d, base_dir) for d in scenario.scene.distractors)
    scene = dataclasses.replace(scenario.scene, distractors=distractors)
    return dataclasses.replace(
        scenario, object=obj, trajectory=trajectory, camera=camera, scene=scene
    )


def _resolve_distractor(distractor: DistractorConfig, base_dir: Path) -> DistractorConfig:
    """A distractor's relative mesh file (``name`` ending in .obj/.ply/.stl) and trajectory file,
    resolved against the scenario file's folder."""
    name = distractor.name
    if Path(name).suffix.lower() in (".obj", ".ply", ".stl") and not Path(name).is_absolute():
        distractor = dataclasses.replace(distractor, name=str(base_dir / name))
    traj_path = getattr(distractor.trajectory, "path", None)
    if isinstance(traj_path, Path) and not traj_path.is_absolute():
        trajectory = dataclasses.replace(distractor.trajectory, path=base_dir / traj_path)  # type: ignore[type-var]
        distractor = dataclasses.replace(distractor, trajectory=trajectory)
    return distractor
