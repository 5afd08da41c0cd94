"""Resolving a run's inputs for one sequence: pose set, mask set, flow source, object model.

The harness turns the ``auto`` / ``gt`` / ``none`` choices of
:class:`~roft_sim.harness.options.RunOptions` into concrete inputs for the
:class:`~roft_sim.faults.ObservationStream`. The ground-truth ablations are fed here and only
here, through the detection channels the fault stream already delays and drops like any
detector's output: :class:`WithGroundTruthPoses` exposes the sequence's ground truth as a pose
set named ``gt``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from roft_sim.datasets.base import GT_MASK_SET, Sequence
from roft_sim.datasets.frames import GT_FULL_MASK_SET
from roft_sim.errors import AssetNotFoundError, ConfigError
from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.harness.options import AUTO, GT_SET, NO_SET, RunOptions
from roft_sim.harness.pose_sets import WithGroundTruthPoses, WithRedrawnPoses, redraw_seed
from roft_sim.records import DepthRenderer, ObjectModel

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]

__all__ = [
    "WithGroundTruthPoses",
    "ResolvedInputs",
    "resolve_inputs",
    "check_inputs",
    "resolve_object_model",
    "LazyDepthRenderer",
    "DepthRendererFactory",
    "mujoco_depth_renderer",
    "PREFERRED_POSE_SET",
    "PREFERRED_FLOW_SET",
]

PREFERRED_POSE_SET = "dope"
"""The pose set ``auto`` picks first (the reference's DOPE set)."""
PREFERRED_FLOW_SET = "nvof_1_slow"
"""The stored flow set ``auto`` picks first (the reference's NVOF 1.0 set)."""

DepthRendererFactory = Callable[[ObjectModel], DepthRenderer]
"""Builds the depth renderer of one object (injected into trackers that need one)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class ResolvedInputs:
    """The concrete inputs of one sequence (what ``auto`` became)."""

    sequence: Sequence
    """The sequence the stream reads (wrapped when ground-truth poses are fed)."""
    pose_set: str | None
    """Pose set the detections come from; None = no pose detections."""
    mask_set: str | None
    """Mask set; None = no masks."""
    flow: str | None
    """Flow source spec; None = no flow."""

    def describe(self) -> dict[str, str | None]:
        """JSON-ready ``{"poses", "masks", "flow"}``."""
        return {"poses": self.pose_set, "masks": self.mask_set, "flow": self.flow}


def _resolve_pose_set(sequence: Sequence, choice: str) -> tuple[Sequence, str | None]:
    available = tuple(sequence.pose_sets())
    if choice == NO_SET:
        return sequence, None
    if choice.startswith("redraw:"):  # a fresh draw of the pose detector (pose_sets)
        seed = redraw_seed(choice)
        assert seed is not None
        return WithRedrawnPoses(sequence, seed), choice
    if choice == GT_SET:
        if GT_SET in available:
            return sequence, GT_SET
        return WithGroundTruthPoses(sequence), GT_SET
    if choice == AUTO:
        detectors = [s for s in available if s != GT_SET]
        if PREFERRED_POSE_SET in detectors:
            return sequence, PREFERRED_POSE_SET
        if detectors:
            return sequence, detectors[0]
        raise ConfigError(
            f"sequence {sequence.name!r} has no detector pose set (sets: {list(available)}); "
            "pass --poses gt to feed its ground truth as detections, or --poses none"
        )
    if choice not in available:
        raise ConfigError(
            f"sequence {sequence.name!r} has no pose set {choice!r}; available: "
            f"{list(available)}, or gt / none / auto"
        )
    return sequence, choice


def _resolve_mask_set(sequence: Sequence, choice: str) -> str | None:
    available = tuple(sequence.mask_sets())
    if choice == NO_SET:
        return None
    if choice == AUTO:
        detectors = [s for s in available if s not in (GT_MASK_SET, GT_FULL_MASK_SET)]
        if not detectors:
            raise ConfigError(
                f"sequence {sequence.name!r} has no detector mask set (sets: {list(available)});"
                " pass --masks gt for ground-truth masks or --masks none"
            )
        return detectors[0]
    if choice not in available:
        raise ConfigError(
            f"sequence {sequence.name!r} has no mask set {choice!r}; available: "
            f"{list(available)}, or none / auto"
        )
    return choice


def _resolve_flow(sequence: Sequence, choice: str) -> str | None:
    if choice == NO_SET:
        return None
    if choice != AUTO:
        return choice
    stored = [s for s in sequence.flow_sets() if s != GT_SET]
    if PREFERRED_FLOW_SET in stored:
        return f"stored:{PREFERRED_FLOW_SET}"
    if stored:
        return f"stored:{stored[0]}"
    return "dis"


def resolve_inputs(sequence: Sequence, options: RunOptions) -> ResolvedInputs:
    """Turns the ``auto`` / ``gt`` / ``none`` choices of ``options`` into this sequence's inputs.

    Raises:
        ConfigError: a requested set does not exist (the message lists the available ones).
    """
    stream_sequence, pose_set = _resolve_pose_set(sequence, options.poses)
    return ResolvedInputs(
        sequence=stream_sequence,
        pose_set=pose_set,
        mask_set=_resolve_mask_set(sequence, options.masks),
        flow=_resolve_flow(sequence, options.flow),
    )


def check_inputs(sequence: Sequence, options: RunOptions) -> ResolvedInputs:
    """Checks, without reading images, that a run of ``options`` can be fed from ``sequence``:
    its pose and mask sets, the flow spec (and a stored flow set it names), the network rates
    against the camera fps. Callers run it before they touch an output folder.

    Raises:
        ConfigError: the first problem found, saying what is available.
    """
    from roft_sim.sensors.flow_sources import (
        NvofLikeFlowSource,
        StoredFlowSource,
        make_flow_source,
    )

    inputs = resolve_inputs(sequence, options)
    if inputs.flow is not None:
        source = make_flow_source(inputs.flow, seed=0)
        while isinstance(source, NvofLikeFlowSource):
            source = source.inner
        if isinstance(source, StoredFlowSource):
            source.check_sequence(sequence)
    options.faults.check_camera_rate(int(sequence.fps))
    return inputs


def resolve_object_model(
    sequence: Sequence, *, assets_dir: Path | None = None, cache_dir: Path | None = None
) -> ObjectModel:
    """The object model of a sequence: the one it carries (with a mesh), else the registry's.

    A dataset that stores model points but no mesh (faces) gets the registry object's mesh only
    if its model points match; otherwise the dataset's points are kept, with no mesh.

    Raises:
        AssetNotFoundError: neither the dataset nor the object registry has a model for it.
    """
    model = sequence.object_model()
    if model is not None and len(model.faces) > 0:
        return model
    from roft_sim.assets import UnknownObjectError, load_object

    try:
        assets = load_object(sequence.object_name, assets_dir=assets_dir, cache_dir=cache_dir)
    except UnknownObjectError as e:
        if model is not None:
            return model
        raise AssetNotFoundError(
            f"sequence {sequence.name!r}: no object model in the dataset and object "
            f"{sequence.object_name!r} is not in the registry ({e}); add models/<object>/"
            "points.xyz (and mesh.obj) to the sequence"
        ) from None
    if model is None:
        return assets.model
    # The dataset's own points define the metric; borrow the registry mesh for rendering.
    return ObjectModel(
        name=model.name,
        vertices_m=np.asarray(assets.model.vertices_m),
        faces=np.asarray(assets.model.faces),
        model_points_m=model.model_points_m,
        mesh_path=assets.model.mesh_path,
    )


def mujoco_depth_renderer(model: ObjectModel) -> DepthRenderer:
    """The MuJoCo depth renderer of ``model`` (imports MuJoCo: the caller must have chosen the
    OpenGL backend, ``MUJOCO_GL``, before the first call)."""
    from roft_sim.render.depth_renderer import MujocoDepthRenderer

    return MujocoDepthRenderer(model)


class LazyDepthRenderer:
    """A :class:`~roft_sim.records.DepthRenderer` built on first use.

    Trackers that declare ``needs_depth_renderer`` get one of these; a configuration that never
    renders (e.g. ROFT with outlier rejection off) never builds the real renderer, so the run
    stays free of MuJoCo and OpenGL.
    """

    def __init__(self, factory: DepthRendererFactory, model: ObjectModel) -> None:
        self._factory = factory
        self._model = model
        self._renderer: DepthRenderer | None = None

    @property
    def built(self) -> bool:
        """True once the real renderer exists."""
        return self._renderer is not None

    def render_depth(self, T_cam_obj: F64, intrinsics: CameraIntrinsics) -> F32:
        """(N, H, W) float32 z-depth [m] of the object at poses ``T_cam_obj`` (N, 4, 4)."""
        if self._renderer is None:
            self._renderer = self._factory(self._model)
        return self._renderer.render_depth(T_cam_obj, intrinsics)
