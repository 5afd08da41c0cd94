"""The datasets and the collate function of :mod:`roft_sim.torch` (see its docstring)."""

from __future__ import annotations

import os
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray
from torch.utils.data import Dataset, IterableDataset, get_worker_info

from roft_sim.datasets import GT_MASK_SET, list_sequences, open_sequence
from roft_sim.datasets.base import Sequence as DatasetSequence
from roft_sim.datasets.frames import DatasetFrame
from roft_sim.errors import ConfigError
from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.records import FlowField, PoseTrack
from roft_sim.scenario import Scenario

F64 = NDArray[np.float64]
Sample = dict[str, Any]

__all__ = [
    "SequenceDataset",
    "GeneratorDataset",
    "collate",
    "sample_from_frame",
    "scenario_seed",
    "AUTO",
    "IMAGE_KEYS",
    "OPTIONAL_KEYS",
]

AUTO = "auto"
"""Pick the set automatically (see :class:`SequenceDataset`)."""
IMAGE_KEYS = ("rgb", "depth", "mask", "detector_mask", "flow", "flow_valid")
"""Keys whose tensors :func:`collate` pads, with ``<key>_size`` (their size can differ)."""
OPTIONAL_KEYS = ("detector_mask",)
"""Keys that may be None (a detector miss): :func:`collate` adds ``<key>_present``."""


def _pick(
    choice: str | None, available: Sequence[str], prefer: Sequence[str], what: str
) -> str | None:
    """A set name: ``choice`` (checked), None, or ``auto``: the first of ``prefer`` available,
    else the first available, else None."""
    if choice is None:
        return None
    if choice != AUTO:
        if choice not in available:
            raise ConfigError(f"no {what} set {choice!r}; available: {list(available)}")
        return choice
    for name in prefer:
        if name in available:
            return name
    return available[0] if available else None


def _flow_tensors(
    flow: FlowField | None, shape: tuple[int, int]
) -> tuple[torch.Tensor, torch.Tensor]:
    if flow is None:
        return torch.zeros((2, *shape), dtype=torch.float32), torch.zeros(shape, dtype=torch.bool)
    values = torch.from_numpy(np.ascontiguousarray(flow.flow_px.transpose(2, 0, 1), np.float32))
    valid = np.isfinite(flow.flow_px).all(axis=2)
    if flow.valid is not None:
        valid &= flow.valid
    return torch.nan_to_num(values), torch.from_numpy(valid)


def _sample(
    *,
    name: str,
    k: int,
    t_s: float,
    rgb: NDArray[np.uint8],
    depth_m: NDArray[np.float32],
    intrinsics: CameraIntrinsics,
    gt_mask: NDArray[np.bool_] | None,
    detector_mask: NDArray[np.bool_] | None,
    flow: FlowField | None,
    flow_shape: tuple[int, int],
    T_cam_obj: F64 | None,
    v_obj_mps: F64 | None,
    w_radps: F64 | None,
) -> Sample:
    flow_px, flow_valid = _flow_tensors(flow, flow_shape)
    pose = np.full((4, 4), np.nan) if T_cam_obj is None else np.asarray(T_cam_obj, np.float64)
    velocity = np.full(6, np.nan)
    if v_obj_mps is not None and w_radps is not None:
        velocity = np.concatenate([v_obj_mps, w_radps]).astype(np.float64)
    sample: Sample = {
        "sequence": name,
        "k": torch.tensor(k, dtype=torch.int64),
        "t_s": torch.tensor(t_s, dtype=torch.float64),
        "rgb": torch.from_numpy(np.ascontiguousarray(np.asarray(rgb).transpose(2, 0, 1))),
        "depth": torch.from_numpy(np.asarray(depth_m, np.float32)[None].copy()),
        "detector_mask": None if detector_mask is None else torch.from_numpy(detector_mask.copy()),
        "flow": flow_px,
        "flow_valid": flow_valid,
        "pose": torch.from_numpy(pose.copy()),
        "velocity": torch.from_numpy(velocity),
        "intrinsics": torch.from_numpy(intrinsics.K),
    }
    if gt_mask is not None:
        sample["mask"] = torch.from_numpy(np.asarray(gt_mask, bool).copy())
    return sample


def sample_from_frame(
    frame: DatasetFrame,
    intrinsics: CameraIntrinsics,
    name: str,
    *,
    flow_set: str | None = AUTO,
    mask_set: str | None = AUTO,
) -> Sample:
    """The item of a generated :class:`~roft_sim.datasets.DatasetFrame` (module docstring).

    Args:
        frame: the frame.
        intrinsics: the camera of its sequence.
        name: the sequence name.
        flow_set: the flow set (``auto``: ``gt``, else the first; None: zeros); frame 0 has no
            flow and gets zeros of the image size.
        mask_set: the detector mask set (``auto``: the first; None: no detector mask).
    """
    flows = tuple(frame.flows)
    flow_name = _pick(flow_set, flows, ("gt",), "flow") if frame.k > 0 else None
    mask_name = _pick(mask_set, tuple(frame.detector_masks), (), "mask")
    return _sample(
        name=name,
        k=frame.k,
        t_s=frame.t_s,
        rgb=frame.rgb,
        depth_m=frame.depth_m,
        intrinsics=intrinsics,
        gt_mask=frame.gt_mask,
        detector_mask=None if mask_name is None else frame.detector_masks[mask_name],
        flow=None if flow_name is None else frame.flows[flow_name],
        flow_shape=intrinsics.shape,
        T_cam_obj=frame.gt_T_cam_obj,
        v_obj_mps=frame.gt_v_obj_mps,
        w_radps=frame.gt_w_radps,
    )


class SequenceDataset(Dataset[Sample]):
    """Every frame of the sequences under ``paths`` (module docstring for an item).

    Args:
        paths: sequence folders, ``.h5`` files or dataset roots (any of our formats or the real
            Fast-YCB), or opened :class:`~roft_sim.datasets.Sequence` objects.
        flow_set: flow set of ``flow`` (``auto``: ``gt``, else ``nvof_1_slow``, else the first;
            None: zeros). Frame 0 gets zeros on the grid of frame 1.
        mask_set: detector mask set of ``detector_mask`` (``auto``: the first set other than
            the ground truth; None: always None).

    Readers are opened in ``__init__`` and pickle, so DataLoader workers get their own copies.
    """

    def __init__(
        self,
        paths: Sequence[str | Path | DatasetSequence] | str | Path,
        *,
        flow_set: str | None = AUTO,
        mask_set: str | None = AUTO,
    ) -> None:
        if isinstance(paths, str | Path):
            paths = [paths]
        self.sequences: list[DatasetSequence] = []
        for p in paths:
            if isinstance(p, str | Path):
                self.sequences.extend(open_sequence(s) for s in list_sequences(p))
            else:
                self.sequences.append(p)
        if not self.sequences:
            raise ConfigError(f"no sequence found under {list(map(str, paths))}")
        self._flow_sets = [
            _pick(flow_set, s.flow_sets(), ("gt", "nvof_1_slow"), "flow") for s in self.sequences
        ]
        self._mask_sets = [
            _pick(mask_set, [m for m in s.mask_sets() if not m.startswith(GT_MASK_SET)], (), "mask")
            for s in self.sequences
        ]
        self._starts = np.cumsum([0, *(len(s) for s in self.sequences)])
        self._ground_truth: dict[int, PoseTrack | None] = {}  # by sequence index, read once

    def __len__(self) -> int:
        return int(self._starts[-1])

    def locate(self, index: int) -> tuple[int, int]:
        """``(sequence index, frame k)`` of item ``index``."""
        if not 0 <= index < len(self):
            raise IndexError(f"index {index} outside 0..{len(self) - 1}")
        i = int(np.searchsorted(self._starts, index, side="right")) - 1
        return i, index - int(self._starts[i])

    def __getitem__(self, index: int) -> Sample:
        i, k = self.locate(index)
        seq = self.sequences[i]
        flow_set, mask_set = self._flow_sets[i], self._mask_sets[i]
        flow = None if flow_set is None else seq.flow(k, flow_set)
        shape = seq.intrinsics.shape
        if flow is None and flow_set is not None and len(seq) > 1:
            first = seq.flow(1, flow_set)
            shape = first.flow_px.shape[:2] if first is not None else shape
        if i not in self._ground_truth:  # a whole-sequence read: not once per item
            self._ground_truth[i] = seq.ground_truth()
        gt = self._ground_truth[i]
        return _sample(
            name=seq.name,
            k=k,
            t_s=seq.time_s(k),
            rgb=seq.rgb(k),
            depth_m=seq.depth(k),
            intrinsics=seq.intrinsics,
            gt_mask=seq.mask(k, GT_MASK_SET) if GT_MASK_SET in seq.mask_sets() else None,
            detector_mask=None if mask_set is None else seq.mask(k, mask_set),
            flow=flow,
            flow_shape=shape,
            T_cam_obj=None if gt is None else gt.T_cam_obj[k],
            v_obj_mps=None if gt is None else gt.v_obj_mps[k],
            w_radps=None if gt is None else gt.w_radps[k],
        )


def scenario_seed(seed: int, index: int) -> int:
    """The seed :class:`GeneratorDataset` gives scenario ``index``: a 31-bit draw of
    ``SeedSequence(seed, spawn_key=(index,))``."""
    return int(np.random.SeedSequence(seed, spawn_key=(index,)).generate_state(1)[0] >> 1)


class GeneratorDataset(IterableDataset[Sample]):
    """Renders ``scenarios`` frame by frame and yields their items (module docstring).

    Scenario ``i`` is rendered with seed :func:`scenario_seed` ``(seed, i)`` (textures, depth
    noise, networks; its trajectory keeps its own), by worker ``i % num_workers``, which opens
    one renderer (one OpenGL context) at a time, in the worker. The items of one scenario come
    in frame order; with several workers the DataLoader interleaves scenarios, but every item
    is the same whatever the number of workers.

    Args:
        scenarios: the scenarios (e.g. ``roft_sim.scenario.load_scenario``).
        seed: base seed.
        flow_set, mask_set: as :func:`sample_from_frame`.
        assets_dir, cache_dir: where real YCB meshes are looked for.
    """

    def __init__(
        self,
        scenarios: Sequence[Scenario],
        *,
        seed: int = 0,
        flow_set: str | None = AUTO,
        mask_set: str | None = AUTO,
        assets_dir: str | Path | None = None,
        cache_dir: str | Path | None = None,
    ) -> None:
        if not scenarios:
            raise ConfigError("GeneratorDataset needs at least one scenario")
        if seed < 0:
            raise ConfigError(f"seed must be >= 0, got {seed}")
        from roft_sim.generation import ScenarioOverrides

        self.scenarios = [
            ScenarioOverrides(seed=scenario_seed(seed, i)).apply(s) for i, s in enumerate(scenarios)
        ]
        self.flow_set, self.mask_set = flow_set, mask_set
        self.assets_dir, self.cache_dir = assets_dir, cache_dir

    def __len__(self) -> int:
        return sum(s.n_frames for s in self.scenarios)

    def __iter__(self) -> Iterator[Sample]:
        from roft_sim.generation.sequence_generator import SequenceGenerator
        from roft_sim.render.gl_backend import select_gl_backend

        select_gl_backend(os.environ)  # in the worker, before MuJoCo opens a context
        info = get_worker_info()
        worker, workers = (0, 1) if info is None else (info.id, info.num_workers)
        for i in range(worker, len(self.scenarios), workers):
            scenario = self.scenarios[i]
            with SequenceGenerator(
                scenario, assets_dir=self.assets_dir, cache_dir=self.cache_dir
            ) as generator:
                for frame in generator.frames(0, scenario.n_frames):
                    yield sample_from_frame(
                        frame,
                        scenario.intrinsics,
                        scenario.name,
                        flow_set=self.flow_set,
                        mask_set=self.mask_set,
                    )


def _pad_stack(values: Sequence[torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor | None]:
    """Stacks tensors of one rank, zero-padding each dimension to the largest; also returns
    their (B, ndim) sizes when they differ (None when all are the same)."""
    shapes = {tuple(v.shape) for v in values}
    if len(shapes) == 1:
        return torch.stack(list(values)), None
    ranks = {len(s) for s in shapes}
    if len(ranks) != 1:
        raise ValueError(f"cannot batch tensors of different ranks: {sorted(shapes)}")
    size = [max(s[d] for s in shapes) for d in range(ranks.pop())]
    out = values[0].new_zeros((len(values), *size))
    for i, v in enumerate(values):
        region: tuple[int | slice, ...] = (i, *(slice(0, n) for n in v.shape))
        out[region] = v
    return out, torch.tensor([list(v.shape) for v in values], dtype=torch.int64)


def collate(batch: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Batches items of :class:`SequenceDataset` / :class:`GeneratorDataset`.

    Tensors are stacked. Images, masks and flow (:data:`IMAGE_KEYS`) of different sizes (sequences
    of other resolutions) are zero-padded to the largest, and ``<key>_size`` (B, ndim) int64
    gives each one's shape. ``detector_mask`` (:data:`OPTIONAL_KEYS`) is None on a detector miss:
    zeros there, and ``<key>_present`` (B,) bool says which items had one (all None: the value
    is a list of None). Every batch has the same keys. Strings become lists.

    Raises:
        ValueError: items with different keys, or tensors of different ranks under one key.
    """
    if not batch:
        raise ValueError("cannot collate an empty batch")
    keys = set(batch[0])
    for item in batch:
        if set(item) != keys:
            raise ValueError(f"items have different keys: {sorted(keys)} and {sorted(item)}")
    out: dict[str, Any] = {}
    for key in batch[0]:
        values = [item[key] for item in batch]
        if all(isinstance(v, str) for v in values):
            out[key] = values
            continue
        present = [v is not None for v in values]
        if key in OPTIONAL_KEYS:
            out[f"{key}_present"] = torch.tensor(present, dtype=torch.bool)
        if not any(present):
            out[key] = values
            continue
        template = next(v for v in values if v is not None)
        filled = [v if v is not None else torch.zeros_like(template) for v in values]
        stacked, sizes = _pad_stack(filled)
        out[key] = stacked
        if key in IMAGE_KEYS:
            out[f"{key}_size"] = (
                sizes
                if sizes is not None
                else torch.tensor([list(v.shape) for v in filled], dtype=torch.int64)
            )
    return out
