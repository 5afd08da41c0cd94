"""The simulated networks a generated dataset holds: a scenario's ``[networks]`` table.

``roft-sim generate`` runs every configured network on EVERY frame (as the reference ran DOPE and
Mask R-CNN offline on every Fast-YCB frame; rate, delay and faults are applied later, when the
dataset is consumed) and writes each as a named set:

- ``[networks.pose]``: the DOPE-like pose estimator (:class:`PoseEstimatorConfig` under
  ``[networks.pose.estimator]``), written as pose set ``dope`` (``dope/poses.txt``; a miss is a
  row of seven zeros);
- ``[networks.mask]``: the Mask R-CNN-like segmenter (``[networks.mask.segmenter]``), written as
  mask set ``mrcnn_ycbv_bop_pbr`` (``masks/mrcnn_ycbv_bop_pbr/<object>_<k>.png``; a miss has no
  file);
- ``[[networks.flow_sets]]``: flow sets, each a name, a source and an on-disk encoding. Default:
  ``gt`` (exact ground-truth motion field, float32, full resolution) and ``nvof_1_slow`` (the
  exact flow with an error model fitted to real NVIDIA hardware flow, in NVOF 1.0's output: one
  vector per 4x4 block in S10.5 int16; :mod:`roft_sim.sensors.nvof_error_model`).

The default set names are the reference's (``dope``, ``mrcnn_ycbv_bop_pbr``, ``nvof_1_slow``), so
the reference ROFT scripts read a generated dataset unchanged; what produced each set is recorded
in the dataset's ``metadata.json``. Every key, unit and default: ``docs/generate.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from roft_sim.datasets.base import GT_FLOW_SET
from roft_sim.datasets.frames import FLOW_ENCODINGS, check_set_name
from roft_sim.errors import ConfigError
from roft_sim.sensors.block_matching import BlockMatchingConfig
from roft_sim.sensors.flow_sources import DIS_PRESETS, FlowNoiseConfig
from roft_sim.sensors.nvof_error_model import NvofErrorModelConfig
from roft_sim.sensors.pose_estimator import FAST_YCB_DOPE, PoseEstimatorConfig
from roft_sim.sensors.segmenter import SegmenterConfig

__all__ = [
    "PoseSetConfig",
    "MaskSetConfig",
    "FlowSetConfig",
    "NetworksConfig",
    "FlowSourceSpec",
    "parse_generation_flow_source",
    "GENERATION_FLOW_SOURCES",
    "DEFAULT_FLOW_SETS",
]

GENERATION_FLOW_SOURCES = (
    "gt",
    "gt+noise",
    "dis[:<preset>]",
    "bm[:<window_px>]",
    "nvof-like:<inner>",
    "nvof-model",
)
"""The flow sources a generated flow set can use (``<inner>`` is any of the first four)."""


def _check_name(kind: str, name: str, *, reserved: tuple[str, ...]) -> None:
    try:
        check_set_name(kind, name)
    except ValueError as e:
        raise ConfigError(str(e)) from None
    if name in reserved:
        raise ConfigError(f"{kind} set name {name!r} is reserved for ground truth; pick another")


@dataclass(frozen=True, slots=True)
class FlowSourceSpec:
    """A parsed flow-source string (see :func:`parse_generation_flow_source`)."""

    kind: Literal["gt", "gt+noise", "dis", "bm", "nvof-like", "nvof-model"]
    """The source."""
    dis_preset: str | None = None
    """OpenCV DIS preset (``kind == "dis"``)."""
    bm_window_px: int | None = None
    """Matching window of the block matcher [px] (``kind == "bm"``; default 8,
    ``roft_sim.sensors.block_matching.BlockMatchingConfig``)."""
    inner: FlowSourceSpec | None = None
    """The source reduced to NVOF's 4x4 grid (``kind == "nvof-like"``)."""

    def uses(self, kind: str) -> bool:
        """True when this source or its inner source is ``kind``."""
        return self.kind == kind or (self.inner is not None and self.inner.uses(kind))


def parse_generation_flow_source(spec: str) -> FlowSourceSpec:
    """Parses a flow-set source: ``gt``, ``gt+noise``, ``dis``, ``dis:<preset>``, ``bm``,
    ``bm:<window_px>``, ``nvof-like:<one of those>`` or ``nvof-model``.

    Raises:
        ConfigError: anything else (the message lists the forms).
    """
    kind, _, arg = spec.strip().partition(":")
    if kind in ("gt", "gt+noise", "nvof-model") and not arg:
        return FlowSourceSpec(kind)  # type: ignore[arg-type]
    if kind == "dis":
        preset = arg or "medium"
        if preset not in DIS_PRESETS:
            raise ConfigError(
                f"flow source {spec!r}: unknown DIS preset {preset!r}; expected one of "
                f"{', '.join(DIS_PRESETS)}"
            )
        return FlowSourceSpec("dis", dis_preset=preset)
    if kind == "bm":
        if arg and not arg.isdigit():
            raise ConfigError(
                f"flow source {spec!r}: 'bm:<window_px>' needs a whole number of pixels, "
                "e.g. 'bm:16'"
            )
        window_px = int(arg) if arg else BlockMatchingConfig().window_px
        BlockMatchingConfig(window_px=window_px)  # checks the window
        return FlowSourceSpec("bm", bm_window_px=window_px)
    if kind == "nvof-like" and arg:
        inner = parse_generation_flow_source(arg)
        if inner.kind in ("nvof-like", "nvof-model"):
            raise ConfigError(
                f"flow source {spec!r}: nvof-like cannot wrap {inner.kind} (already on NVOF's "
                "4x4 grid)"
            )
        return FlowSourceSpec("nvof-like", inner=inner)
    raise ConfigError(
        f"unknown flow source {spec!r}; expected one of {', '.join(GENERATION_FLOW_SOURCES)}, "
        "e.g. 'gt' or 'nvof-like:dis'"
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class PoseSetConfig:
    """The DOPE-like pose estimator and the pose set it is written as (``[networks.pose]``)."""

    enabled: bool = True
    """Write the pose set."""
    set_name: str = "dope"
    """Pose set name: Fast-YCB ``<set_name>/poses.txt``; BOP/HDF5 extras under this name."""
    estimator: PoseEstimatorConfig = field(default_factory=PoseEstimatorConfig)
    """Error statistics (``[networks.pose.estimator]``; defaults calibrated to the paper's
    pooled "DOPE (ideal)" row, docs/sensors.md). Used for every object when given (any field
    differs from the defaults) or when ``calibration = "none"``, else for objects without a
    per-object calibration."""
    calibration: Literal["fast-ycb", "none"] = "fast-ycb"
    """``fast-ycb``: a Fast-YCB object (``003_cracker_box`` ... ``010_potted_meat_can``) whose
    ``estimator`` is left at its defaults gets its own fit to the paper's Table I DOPE column
    (:data:`~roft_sim.sensors.pose_estimator.FAST_YCB_DOPE`, docs/sensors.md); ``none``: every
    object gets ``estimator``."""

    def __post_init__(self) -> None:
        _check_name("pose", self.set_name, reserved=("gt",))
        if self.calibration not in ("fast-ycb", "none"):
            raise ConfigError(
                f"networks.pose.calibration must be 'fast-ycb' or 'none', got {self.calibration!r}"
            )

    def estimator_for(self, object_name: str | Path) -> PoseEstimatorConfig:
        """The error statistics used for ``object_name`` (a registry name or a mesh path)."""
        if (
            self.calibration == "fast-ycb"
            and isinstance(object_name, str)
            and object_name in FAST_YCB_DOPE
            and self.estimator == PoseEstimatorConfig()
        ):
            return FAST_YCB_DOPE[object_name]
        return self.estimator


@dataclass(frozen=True, slots=True, kw_only=True)
class MaskSetConfig:
    """The Mask R-CNN-like segmenter and the mask set it is written as (``[networks.mask]``)."""

    enabled: bool = True
    """Write the mask set."""
    set_name: str = "mrcnn_ycbv_bop_pbr"
    """Mask set name: Fast-YCB ``masks/<set_name>/<object>_<k>.png``."""
    segmenter: SegmenterConfig = field(default_factory=SegmenterConfig)
    """Error model (``[networks.mask.segmenter]``, docs/sensors.md)."""

    def __post_init__(self) -> None:
        _check_name("mask", self.set_name, reserved=("gt", "gt_full"))


@dataclass(frozen=True, slots=True, kw_only=True)
class FlowSetConfig:
    """One flow set written for every frame k >= 1: ``F_k`` from frame k-1 to k
    (``[[networks.flow_sets]]``)."""

    set_name: str
    """Flow set name: Fast-YCB ``optical_flow/<set_name>/<k>.float``."""
    source: str
    """``gt`` (exact motion field, with validity), ``gt+noise`` (gt plus the ``noise`` model),
    ``dis[:ultrafast|fast|medium|medium4]`` (OpenCV DIS on the rendered rgb, default preset
    medium; medium4 = medium stopped at 1/4 resolution, 4 times cheaper, less accurate),
    ``bm[:<window_px>]`` (block matching on the rendered rgb, one vector per 4x4 block, default
    window 8 px; ``nvof-like:bm:16`` is the flow closest to Fast-YCB's real NVOF picture,
    docs/fidelity.md, at about 45 times DIS medium's time), ``nvof-like:<one of those>``
    (reduced to NVOF 1.0's one vector per 4x4 block, rounded to 1/4 px) or ``nvof-model`` (the
    exact flow with the error model fitted to real NVIDIA hardware flow, ``nvof_model``)."""
    encoding: Literal["float32", "s10.5"] = "float32"
    """On-disk encoding: ``float32`` (exact) or ``s10.5`` (int16, 1/32 px steps, |F| < 1024 px,
    as NVOF writes; lossy for sources finer than 1/32 px)."""
    noise: FlowNoiseConfig = field(default_factory=FlowNoiseConfig)
    """End-point-error model of a ``gt+noise`` source (``[networks.flow_sets.noise]``)."""
    nvof_model: NvofErrorModelConfig = field(default_factory=NvofErrorModelConfig)
    """Error model of an ``nvof-model`` source (``[networks.flow_sets.nvof_model]``; defaults
    fitted to real hardware flow, :mod:`roft_sim.sensors.nvof_error_model`)."""

    def __post_init__(self) -> None:
        _check_name("flow", self.set_name, reserved=())
        parse_generation_flow_source(self.source)
        if self.encoding not in FLOW_ENCODINGS:
            raise ConfigError(
                f"flow set {self.set_name!r}: encoding {self.encoding!r}; expected one of "
                f"{', '.join(FLOW_ENCODINGS)}"
            )

    @property
    def source_spec(self) -> FlowSourceSpec:
        """The parsed :attr:`source`."""
        return parse_generation_flow_source(self.source)


DEFAULT_FLOW_SETS: tuple[FlowSetConfig, ...] = (
    FlowSetConfig(set_name=GT_FLOW_SET, source="gt", encoding="float32"),
    FlowSetConfig(set_name="nvof_1_slow", source="nvof-model", encoding="s10.5"),
)
"""``gt``: exact float flow; ``nvof_1_slow``: an NVOF-1.0-like estimate (the exact flow with the
error model fitted to real NVIDIA hardware flow, 4x4, S10.5)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class NetworksConfig:
    """What simulated networks a generated dataset holds (a scenario's ``[networks]`` table).

    The defaults reproduce the reference Fast-YCB layout: pose set ``dope``, mask set
    ``mrcnn_ycbv_bop_pbr``, flow sets ``gt`` and ``nvof_1_slow``.
    """

    pose: PoseSetConfig = field(default_factory=PoseSetConfig)
    """The pose estimator (``[networks.pose]``)."""
    mask: MaskSetConfig = field(default_factory=MaskSetConfig)
    """The segmenter (``[networks.mask]``)."""
    flow_sets: tuple[FlowSetConfig, ...] = DEFAULT_FLOW_SETS
    """The flow sets (``[[networks.flow_sets]]``; giving any replaces the defaults; an empty
    list ``flow_sets = []`` writes none)."""

    def __post_init__(self) -> None:
        names = [f.set_name for f in self.flow_sets]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ConfigError(f"networks.flow_sets: set names {dup} appear more than once")

    @property
    def flow_encodings(self) -> dict[str, str]:
        """Flow set name -> on-disk encoding (what the dataset writers take)."""
        return {f.set_name: f.encoding for f in self.flow_sets}
