"""Fault configurations: per-stream fault lists, loaded strictly from TOML presets or files.

A fault file (``scenarios/faults/<name>.toml``) looks like::

    description = "ROFT paper: pose and mask networks at 5 fps, results 6 frames (200 ms) late"

    [pose]
    first_result = "undelayed"
    faults = [{ kind = "rate", rate_hz = 5 }, { kind = "delay", frames = 6 }]

    [mask]
    first_result = "undelayed"
    faults = [{ kind = "rate", rate_hz = 5 }, { kind = "delay", frames = 6 }]

    [camera]
    faults = [{ kind = "dropout", p = 0.02 }]

Every fault is a table with a ``kind``; unknown kinds or keys are errors that name the key, the
valid ones and the file. See docs/faults.md for every kind, its parameters and units, and the
order in which faults compose.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from roft_sim.config_files import dataclass_from_mapping, load_toml
from roft_sim.errors import ConfigError
from roft_sim.faults.camera import DepthHoles, DepthNoise, FlowHoles, FlowNoise, FlowReversed
from roft_sim.faults.content import (
    EmptyMask,
    MaskMorphology,
    MaskShift,
    RotationFlip,
    SpuriousBlobs,
    TranslationJump,
    WrongFrameMask,
    WrongObject,
)
from roft_sim.faults.delivery import Duplicate, Reorder, Stale
from roft_sim.faults.loss import BernoulliDropout, Blackout, GilbertElliott
from roft_sim.faults.timing import (
    BusyNetwork,
    ClockSkew,
    EmpiricalDelay,
    FixedDelay,
    LogNormalDelay,
    Rate,
    UniformDelay,
)
from roft_sim.shipped_files import scenarios_dir

__all__ = [
    "PoseFault",
    "MaskFault",
    "CameraFault",
    "FlowFault",
    "PoseStreamFaults",
    "MaskStreamFaults",
    "CameraFaults",
    "FlowFaults",
    "FaultConfig",
    "FirstResult",
    "load_faults",
    "list_fault_presets",
    "fault_presets_dir",
    "fault_config_from_mapping",
    "compose_faults",
    "fault_spec_name",
]

_DETECTION_SAMPLING_AND_LOSS = Rate | BusyNetwork | BernoulliDropout | GilbertElliott | Blackout
"""The sampling and loss faults both detection streams accept."""
_DETECTION_TIMING_AND_DELIVERY = (
    ClockSkew
    | FixedDelay
    | UniformDelay
    | LogNormalDelay
    | EmpiricalDelay
    | Duplicate
    | Stale
    | Reorder
)
"""The stamp, delay and delivery faults both detection streams accept."""

PoseFault = (
    _DETECTION_SAMPLING_AND_LOSS
    | TranslationJump
    | RotationFlip
    | WrongObject
    | _DETECTION_TIMING_AND_DELIVERY
)
"""Every fault a pose stream accepts."""
MaskFault = (
    _DETECTION_SAMPLING_AND_LOSS
    | MaskShift
    | MaskMorphology
    | EmptyMask
    | SpuriousBlobs
    | WrongFrameMask
    | _DETECTION_TIMING_AND_DELIVERY
)
"""Every fault a mask stream accepts."""
CameraFault = BernoulliDropout | GilbertElliott | Blackout | DepthHoles | DepthNoise
"""Every fault the camera stream accepts (the loss faults drop whole camera frames)."""
FlowFault = FlowNoise | FlowHoles | FlowReversed
"""Every fault the flow stream accepts."""

FirstResult = Literal["delayed", "undelayed", "undelayed_and_delayed"]
"""How the result of the stream's first network run is delivered:

- ``delayed``: like every other result;
- ``undelayed``: at its capture frame (the reference: the first pose and mask, of frame 0,
  arrive at frame 0);
- ``undelayed_and_delayed``: at its capture frame AND again after the delay, as the reference
  implementation does (its pose of frame 0 is fused at frame 0 and again at frame 6).
"""


@dataclass(frozen=True, slots=True, kw_only=True)
class _DetectionStreamFaults:
    """The options every detection stream has; subclasses narrow the fault types."""

    first_result: FirstResult = "delayed"
    """How the first run's result is delivered (see :data:`FirstResult`)."""
    faults: tuple[Any, ...] = ()
    """The faults; composed by stage (docs/faults.md), listed order within a stage."""

    def __post_init__(self) -> None:
        sampling = [i for i, f in enumerate(self.faults) if f.stage == "sampling"]
        if len(sampling) > 1:
            kinds = ", ".join(f"faults[{i}] ({self.faults[i].kind})" for i in sampling)
            raise ConfigError(
                f"a stream takes at most one sampling fault (rate or busy), got {kinds}; keep one"
            )


@dataclass(frozen=True, slots=True, kw_only=True)
class PoseStreamFaults(_DetectionStreamFaults):
    """Faults of the pose-detection stream."""

    faults: tuple[PoseFault, ...] = ()
    """The faults; composed by stage (docs/faults.md), listed order within a stage."""


@dataclass(frozen=True, slots=True, kw_only=True)
class MaskStreamFaults(_DetectionStreamFaults):
    """Faults of the mask-detection stream."""

    faults: tuple[MaskFault, ...] = ()
    """The faults; composed by stage (docs/faults.md), listed order within a stage."""


@dataclass(frozen=True, slots=True, kw_only=True)
class CameraFaults:
    """Faults of the camera stream: dropped frames (loss faults) and depth corruption."""

    faults: tuple[CameraFault, ...] = ()
    """Loss faults drop whole camera frames; depth faults apply in the listed order."""

    def __post_init__(self) -> None:
        for i, f in enumerate(self.faults):
            if isinstance(f, Blackout) and f.mode == "hold":
                raise ConfigError(
                    f'faults[{i}]: a camera frame cannot be held back; use mode = "drop"'
                )


@dataclass(frozen=True, slots=True, kw_only=True)
class FlowFaults:
    """Faults of the optical-flow stream, applied in the listed order."""

    faults: tuple[FlowFault, ...] = ()
    """Flow corruption faults."""


@dataclass(frozen=True, slots=True, kw_only=True)
class FaultConfig:
    """A complete fault configuration: one fault list per stream, plus seed handling."""

    name: str = "custom"
    """Preset name (the file stem when loaded from a file without a name)."""
    description: str = ""
    """One line saying what the configuration does (``roft-sim faults list``)."""
    seed: int | None = None
    """If set, the fault randomness uses this seed instead of the run's seed (the same faults
    for every run); None = derived from the run's seed."""
    pose: PoseStreamFaults = field(default_factory=PoseStreamFaults)
    """Pose-detection stream."""
    mask: MaskStreamFaults = field(default_factory=MaskStreamFaults)
    """Mask-detection stream."""
    camera: CameraFaults = field(default_factory=CameraFaults)
    """Camera frames (rgb and depth)."""
    flow: FlowFaults = field(default_factory=FlowFaults)
    """Optical flow."""

    def __post_init__(self) -> None:
        if self.seed is not None and self.seed < 0:
            raise ConfigError(f"seed must be >= 0, got {self.seed}")

    def detection_stream(self, stream: str) -> PoseStreamFaults | MaskStreamFaults:
        """The ``pose`` or ``mask`` stream config."""
        if stream == "pose":
            return self.pose
        if stream == "mask":
            return self.mask
        raise ConfigError(f"unknown detection stream {stream!r}; expected 'pose' or 'mask'")

    def check_camera_rate(self, fps: int) -> None:
        """Checks every rate against the camera rate ``fps`` [Hz].

        Raises:
            ConfigError: naming ``<stream>.faults[i]`` when a ``rate_hz`` does not divide fps.
        """
        if fps < 1:
            raise ConfigError(f"camera fps must be a positive integer, got {fps}")
        for where, fault in self.iter_faults():
            if isinstance(fault, Rate):
                try:
                    fault.period(fps)
                except ConfigError as e:
                    raise ConfigError(f"fault config {self.name!r} {where}: {e}") from None

    def iter_faults(self) -> Iterator[tuple[str, Any]]:
        """``(where, fault)`` for every configured fault, ``where`` like ``pose.faults[1]``."""
        for stream in ("pose", "mask", "camera", "flow"):
            for i, fault in enumerate(getattr(self, stream).faults):
                yield f"{stream}.faults[{i}]", fault

    def describe_lines(self) -> list[str]:
        """Human-readable lines, one per stream setting and fault."""
        lines = []
        for stream in ("pose", "mask"):
            cfg = self.detection_stream(stream)
            if cfg.first_result != "delayed":
                lines.append(f"{stream}: first result {cfg.first_result.replace('_', ' ')}")
        for where, fault in self.iter_faults():
            lines.append(f"{where}: {fault.describe()}")
        return lines or ["no faults: every frame's detections arrive at their own frame"]


def _merge_first_result(where: str, values: list[str]) -> str:
    chosen = {v for v in values if v != "delayed"}
    if len(chosen) > 1:
        raise ConfigError(
            f"cannot compose fault configs: {where}.first_result differs ({sorted(chosen)}); "
            "make them agree"
        )
    return chosen.pop() if chosen else "delayed"


def compose_faults(*configs: FaultConfig, name: str | None = None) -> FaultConfig:
    """One configuration with the faults of all ``configs``: per stream, their fault lists
    concatenated in the given order.

    Composition is associative (``compose(compose(a, b), c) == compose(a, compose(b, c))``).
    Swapping two configs changes nothing when their faults commute (loss, delay and stamp
    faults, and faults of different kinds: see docs/faults.md), and changes the result where
    the listed order matters (content faults, delivery faults, two faults of one kind).

    Raises:
        ConfigError: the configs set different non-default ``first_result`` or ``seed``, or
            together have two sampling faults in one stream.
    """
    if not configs:
        return FaultConfig(name=name or "none")
    seeds = {c.seed for c in configs if c.seed is not None}
    if len(seeds) > 1:
        raise ConfigError(f"cannot compose fault configs with different seeds {sorted(seeds)}")
    pose_first = _merge_first_result("pose", [c.pose.first_result for c in configs])
    mask_first = _merge_first_result("mask", [c.mask.first_result for c in configs])
    try:
        return FaultConfig(
            name=name or "+".join(c.name for c in configs),
            description="; ".join(c.description for c in configs if c.description),
            seed=seeds.pop() if seeds else None,
            pose=PoseStreamFaults(
                first_result=pose_first,  # type: ignore[arg-type]
                faults=tuple(f for c in configs for f in c.pose.faults),
            ),
            mask=MaskStreamFaults(
                first_result=mask_first,  # type: ignore[arg-type]
                faults=tuple(f for c in configs for f in c.mask.faults),
            ),
            camera=CameraFaults(faults=tuple(f for c in configs for f in c.camera.faults)),
            flow=FlowFaults(faults=tuple(f for c in configs for f in c.flow.faults)),
        )
    except ConfigError as e:
        names = " + ".join(repr(c.name) for c in configs)
        raise ConfigError(
            f"cannot compose fault configs {names}: {e} (compose a full preset with fragments "
            "that add faults but set no network rate: the stress presets already include the "
            "paper's rate and delay)"
        ) from None


def fault_spec_name(spec: str) -> str:
    """How reports name a fault spec: a fault file (``.../mix-1000.toml``) by its stem, a preset
    or a composed spec (``paper+bursts``) as given."""
    return Path(spec).stem if spec.endswith(".toml") and "+" not in spec else spec


def fault_presets_dir() -> Path:
    """The folder of the preset files, ``scenarios/faults/`` in the repository."""
    return scenarios_dir() / "faults"


def fault_config_from_mapping(
    data: dict[str, Any], *, where: str = "fault config", default_name: str = "custom"
) -> FaultConfig:
    """Builds a :class:`FaultConfig` from a parsed TOML table (strict: unknown keys fail)."""
    if "name" not in data:
        data = {**data, "name": default_name}
    return dataclass_from_mapping(FaultConfig, data, where=where)


def load_faults(name_or_path: str | Path) -> FaultConfig:
    """Loads a preset by name (``none``, ``paper``, ...) or a fault TOML file by path.

    Several presets or files joined by ``+`` (``paper+extra.toml``, where ``extra.toml`` adds
    faults but no network rate) are loaded one by one and composed with
    :func:`compose_faults`.

    Raises:
        ConfigError: unknown preset (listing the presets), missing file, bad TOML, unknown keys
            or invalid values (naming the file and the dotted key).
    """
    text = str(name_or_path)
    if "+" in text and not Path(text).is_file():
        parts = [p.strip() for p in text.split("+")]
        if any(not p for p in parts):
            raise ConfigError(f"empty part in composed fault spec {text!r}; e.g. 'paper+bursts'")
        return compose_faults(*(load_faults(p) for p in parts), name=text)
    path = Path(text)
    if path.suffix == ".toml" or path.is_file() or "/" in text:
        return fault_config_from_mapping(load_toml(path), where=f"{path}:", default_name=path.stem)
    preset = fault_presets_dir() / f"{text}.toml"
    if not preset.is_file():
        names = [n for n, _ in list_fault_presets()]
        close = difflib.get_close_matches(text, names, n=1)
        hint = f"did you mean {close[0]!r}? " if close else ""
        raise ConfigError(
            f"unknown fault preset {text!r}; {hint}presets: {', '.join(names) or '(none found)'}"
            " (or give the path of a .toml fault file)"
        )
    return fault_config_from_mapping(load_toml(preset), where=f"{preset}:", default_name=text)


def list_fault_presets() -> list[tuple[str, str]]:
    """``(name, one-line description)`` of every preset in ``scenarios/faults/``, by name."""
    folder = fault_presets_dir()
    if not folder.is_dir():
        return []
    out = []
    for path in sorted(folder.glob("*.toml"), key=lambda p: p.stem):
        description = load_toml(path).get("description", "")
        out.append((path.stem, str(description).strip().splitlines()[0] if description else ""))
    return out
