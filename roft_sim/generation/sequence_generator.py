"""One scenario's frames as :class:`~roft_sim.datasets.DatasetFrame` objects: render, ground
truth, simulated networks, flow sets.

Per frame ``k`` (docs/generate.md, "The pipeline"):

1. :meth:`SceneRenderer.render_frame` gives rgb, exact z-depth, the sensor depth (the scenario's
   depth-noise model, drawn from ``scenario.rng("depth_noise", k)``), the visible mask, the
   per-pixel body index and the exact pose and velocity.
2. The full silhouette (the object alone, no occluder) is rendered by a
   :class:`~roft_sim.render.MujocoDepthRenderer`; the visible fraction is
   ``|visible| / |visible or full|`` (0 when the object is out of view).
3. Flow sets: ``F_k`` from frame k-1 to k. ``gt`` is :func:`roft_sim.render.ground_truth_flow`
   (every rigid body, the hand included, moves with its own motion); ``gt+noise`` adds
   :func:`~roft_sim.sensors.flow_sources.apply_flow_noise` with the generator
   ``frame_rng(seed_of_set, k-1, k)``; ``nvof-model`` applies
   :func:`~roft_sim.sensors.nvof_error_model.nvof_error_model` (the error model fitted to real
   NVIDIA hardware flow) to that same exact flow with the same generator; ``dis`` and
   ``nvof-like`` are the sensors' own sources run on the two rendered frames.
4. Pose estimator: :func:`~roft_sim.sensors.pose_estimator.sample_pose_detections` over the
   WHOLE ground-truth track (computed from the trajectory without rendering, see
   :func:`ground_truth_track`) with the stream ``scenario.rng("pose_estimator")``; its draws
   depend on the sequence length only and frame k's detection on frame k's pose and visible
   fraction only, so frame k's detection is the same whichever frames a worker renders.
5. Segmenter on the visible mask with ``scenario.rng("segmenter", k)``.

So every frame is a pure function of (scenario, seed, k): frames can be generated in any order
and split among workers in any way, with byte-identical results on the same render backend.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from roft_sim.datasets.frames import DatasetFrame, DistractorTruth
from roft_sim.geometry import CameraIntrinsics, relative_motion
from roft_sim.records import FlowField, PoseTrack
from roft_sim.render.depth_renderer import MujocoDepthRenderer
from roft_sim.render.ground_truth import RenderedFrame, ground_truth_flow
from roft_sim.render.scene_renderer import SceneRenderer
from roft_sim.scenario import Scenario
from roft_sim.scene.camera_motion import camera_poses
from roft_sim.sensors.block_matching import BlockMatchingConfig, BlockMatchingFlowSource
from roft_sim.sensors.flow_sources import (
    DisFlowSource,
    FlowSource,
    NvofLikeFlowSource,
    apply_flow_noise,
    frame_rng,
)
from roft_sim.sensors.networks import FlowSetConfig, FlowSourceSpec
from roft_sim.sensors.nvof_error_model import NvofErrorModelFlowSource
from roft_sim.sensors.pose_estimator import sample_pose_detections
from roft_sim.sensors.segmenter import simulate_mask

F64 = NDArray[np.float64]
Bool = NDArray[np.bool_]

__all__ = [
    "SequenceGenerator",
    "ground_truth_track",
    "visible_fraction",
    "flow_set_seed",
    "POSE_ESTIMATOR_STREAM",
    "SEGMENTER_STREAM",
]

POSE_ESTIMATOR_STREAM = "pose_estimator"
"""Subsystem name of the pose estimator's stream: ``scenario.rng("pose_estimator")``."""
SEGMENTER_STREAM = "segmenter"
"""Subsystem name of the segmenter's per-frame streams: ``scenario.rng("segmenter", k)``."""


def flow_set_seed(scenario: Scenario, set_name: str) -> int:
    """Seed of a flow set's noise: the first 32-bit word of
    ``scenario.seed_sequence("flow:<set_name>")``; frame pair ``(k-1, k)`` then draws from
    ``frame_rng(seed, k-1, k)``."""
    return int(scenario.seed_sequence(f"flow:{set_name}").generate_state(1)[0])


def ground_truth_track(renderer: SceneRenderer) -> PoseTrack:
    """The exact object track of every frame of the renderer's scenario, without rendering.

    Vectorised form of :meth:`SceneRenderer.state_at` at ``t_k = k / fps``: object pose and
    velocity relative to the (possibly moving) camera, camera frame.

    Returns:
        (N,) :class:`PoseTrack` (``T_cam_obj`` [m], ``v_obj_mps``, ``w_radps``).
    """
    scenario = renderer.scenario
    t_s = np.arange(scenario.n_frames, dtype=np.float64) / scenario.fps
    traj = renderer.trajectory
    t_traj = np.clip(float(traj.start_s) + t_s, traj.start_s, traj.end_s)
    sample = traj.sample(t_traj)
    cam = camera_poses(scenario.camera.motion, t_s)
    T_cam_obj, v_obj, w = relative_motion(
        cam.T_world_cam,
        cam.v_world_mps,
        cam.w_world_radps,
        sample.T_ref_obj,
        sample.v_mps,
        sample.w_radps,
    )
    return PoseTrack(t_s=t_s, T_cam_obj=T_cam_obj, v_obj_mps=v_obj, w_radps=w)


def visible_fraction(visible: Bool, full: Bool) -> float:
    """Visible fraction of the object in [0, 1]: ``|visible| / |visible or full|``; 0 when
    neither mask has a pixel.

    Args:
        visible: (H, W) bool visible mask (after occlusion).
        full: (H, W) bool full silhouette (the object alone).
    """
    area = int(np.count_nonzero(visible | full))
    return 0.0 if area == 0 else int(np.count_nonzero(visible)) / area


class _FramePair:
    """Two consecutive rendered frames behind the part of the ``Sequence`` protocol that the
    sensors' flow sources read (rgb, depth, intrinsics), plus a per-pair memo."""

    def __init__(
        self, name: str, intrinsics: CameraIntrinsics, n_frames: int, frames: list[RenderedFrame]
    ) -> None:
        self.name = name
        self.intrinsics = intrinsics
        self._n = n_frames
        self._frames = {f.k: f for f in frames}
        self.memo: dict[str, FlowField | None] = {}

    def __len__(self) -> int:
        return self._n

    def frame(self, k: int) -> RenderedFrame:
        return self._frames[k]

    def rgb(self, k: int) -> NDArray[np.uint8]:
        return self._frames[k].rgb

    def depth(self, k: int) -> NDArray[np.float32]:
        return self._frames[k].sensor_depth_m


class _RenderedGroundTruthFlow:
    """Exact flow from the rendered frames' depth and per-pixel bodies (hand included)."""

    name = "gt"

    def flow(self, pair: Any, from_k: int, to_k: int) -> FlowField:
        if "gt" not in pair.memo:
            pair.memo["gt"] = ground_truth_flow(
                pair.frame(from_k), pair.frame(to_k), pair.intrinsics
            )
        return cast(FlowField, pair.memo["gt"])


class _NoisyRenderedGroundTruthFlow:
    """``gt`` plus a flow set's end-point-error model, drawn per frame pair."""

    name = "gt+noise"

    def __init__(self, config: FlowSetConfig, seed: int) -> None:
        self._gt = _RenderedGroundTruthFlow()
        self._noise = config.noise
        self._seed = seed

    def flow(self, pair: Any, from_k: int, to_k: int) -> FlowField:
        exact = self._gt.flow(pair, from_k, to_k)
        return apply_flow_noise(exact, self._noise, frame_rng(self._seed, from_k, to_k))


class _Memoised:
    """Computes an inner source once per frame pair (``nvof-like:dis`` next to ``dis``)."""

    def __init__(self, inner: FlowSource, key: str) -> None:
        self.inner = inner
        self.key = key
        self.name = inner.name

    def flow(self, pair: Any, from_k: int, to_k: int) -> FlowField | None:
        if self.key not in pair.memo:
            pair.memo[self.key] = self.inner.flow(pair, from_k, to_k)
        return cast("FlowField | None", pair.memo[self.key])


def _flow_source(spec: FlowSourceSpec, config: FlowSetConfig, seed: int) -> FlowSource:
    if spec.kind == "gt":
        return _RenderedGroundTruthFlow()
    if spec.kind == "gt+noise":
        return _NoisyRenderedGroundTruthFlow(config, seed)
    if spec.kind == "dis":
        assert spec.dis_preset is not None
        return _Memoised(DisFlowSource(spec.dis_preset), f"dis:{spec.dis_preset}")
    if spec.kind == "nvof-model":
        return NvofErrorModelFlowSource(
            config.nvof_model, seed, exact=cast(FlowSource, _RenderedGroundTruthFlow())
        )
    if spec.kind == "bm":
        assert spec.bm_window_px is not None
        matcher = BlockMatchingConfig(window_px=spec.bm_window_px)
        return _Memoised(BlockMatchingFlowSource(matcher), f"bm:{spec.bm_window_px}")
    assert spec.inner is not None
    return NvofLikeFlowSource(_flow_source(spec.inner, config, seed))


class SequenceGenerator:
    """Generates the :class:`DatasetFrame` objects of one scenario (see the module doc).

    A context manager: it owns a :class:`SceneRenderer` and a silhouette renderer (OpenGL
    contexts), so create it in the process that uses it, never before a fork.

    Args:
        scenario: what to generate (its ``networks`` table says which sets).
        assets_dir, cache_dir: where real object meshes are looked for
            (``roft_sim.assets.load_object``).
        object_assets, trajectory: already loaded assets / built trajectory (tests, callers that
            share them); passed to :class:`SceneRenderer`.
    """

    def __init__(
        self,
        scenario: Scenario,
        *,
        assets_dir: Any = None,
        cache_dir: Any = None,
        object_assets: Any = None,
        trajectory: Any = None,
    ) -> None:
        self.scenario = scenario
        self.networks = scenario.networks
        self._silhouettes: MujocoDepthRenderer | None = None
        self._distractor_silhouettes: list[MujocoDepthRenderer] = []
        self._unoccluded_detections: tuple[Bool, F64] | None = None
        self._renderer = SceneRenderer(
            scenario,
            assets_dir=assets_dir,
            cache_dir=cache_dir,
            object_assets=object_assets,
            trajectory=trajectory,
            segmentation=True,
        )
        try:
            model = self._renderer.object_assets.mesh
            self._silhouettes = MujocoDepthRenderer(model)
            self._distractor_silhouettes = [
                MujocoDepthRenderer(d.mesh) for d in self._renderer.distractors
            ]
            self.track = ground_truth_track(self._renderer)
            self._flow_sources = {
                f.set_name: _flow_source(f.source_spec, f, flow_set_seed(scenario, f.set_name))
                for f in self.networks.flow_sets
            }
        except BaseException:
            self.close()
            raise

    @property
    def n_frames(self) -> int:
        """Frames of the scenario."""
        return self.scenario.n_frames

    @property
    def renderer(self) -> SceneRenderer:
        """The scene renderer (its ``object_assets`` and ``trajectory`` are the ones used)."""
        return self._renderer

    # ------------------------------------------------------------------------------ frames
    def frames(self, start: int, stop: int, *, pipelined: bool = True) -> Iterator[DatasetFrame]:
        """Frames ``start ... stop-1`` in order (frame ``start - 1`` is rendered too, for the
        flow of frame ``start``).

        With ``pipelined`` the flow sets and simulated networks of frame k are computed on a
        second thread while frame k+1 renders on this one (the OpenGL contexts stay on this
        thread; OpenCV and numpy release the GIL); the frames are the same either way. At most
        three rendered frames are held at a time (two without).

        Raises:
            IndexError: the range is outside ``0 .. n_frames``.
        """
        if not 0 <= start <= stop <= self.n_frames:
            raise IndexError(f"frames {start}..{stop - 1} outside 0..{self.n_frames - 1}")
        previous = self._renderer.render_frame(start - 1) if start > 0 else None
        if not pipelined:
            for k in range(start, stop):
                current = self._renderer.render_frame(k)
                yield self.dataset_frame(current, previous)
                previous = current
            return
        with ThreadPoolExecutor(1, thread_name_prefix="roft-sim-frame") as networks:
            queued: deque[Future[DatasetFrame]] = deque()
            for k in range(start, stop):
                current = self._renderer.render_frame(k)
                # the silhouettes are OpenGL renders: on this thread
                full = self._full_silhouette(current)
                distractors = self._distractor_truths(current)
                queued.append(
                    networks.submit(
                        self.dataset_frame,
                        current,
                        previous,
                        full_silhouette=full,
                        distractors=distractors,
                    )
                )
                previous = current
                if len(queued) > 1:
                    yield queued.popleft().result()
            while queued:
                yield queued.popleft().result()

    def dataset_frame(
        self,
        current: RenderedFrame,
        previous: RenderedFrame | None,
        *,
        full_silhouette: Bool | None = None,
        distractors: tuple[DistractorTruth, ...] | None = None,
    ) -> DatasetFrame:
        """The dataset frame of rendered frame ``current.k``; ``previous`` is frame k-1 (None
        only for k = 0). ``full_silhouette``: the (H, W) bool silhouette of the object alone
        at frame k's pose, and ``distractors``: the distractors' ground truth, when already
        rendered (else they are rendered here, which must then be the OpenGL thread)."""
        k = current.k
        if k > 0 and (previous is None or previous.k != k - 1):
            raise ValueError(f"frame {k} needs the rendered frame {k - 1} for its flow")
        visible = current.object_mask
        assert visible is not None  # rendered with segmentation
        if full_silhouette is None:
            full_silhouette = self._full_silhouette(current)
        full = full_silhouette | visible
        vis = visible_fraction(visible, full)
        nets = self.networks
        flows: dict[str, FlowField] = {}
        if k > 0 and self.networks.flow_sets:
            assert previous is not None
            pair = _FramePair(
                self.scenario.name, self.scenario.intrinsics, self.n_frames, [previous, current]
            )
            for name, source in self._flow_sources.items():
                # a _FramePair has the part of the Sequence protocol that flow sources read
                flow = source.flow(pair, k - 1, k)  # type: ignore[arg-type]
                if flow is None:  # pragma: no cover - our sources always give a flow
                    raise RuntimeError(f"flow source of set {name!r} gave no flow for frame {k}")
                flows[name] = flow
        poses: dict[str, F64 | None] = {}
        if nets.pose.enabled:
            poses[nets.pose.set_name] = self._pose_detection(k, vis)
        masks: dict[str, Bool | None] = {}
        if nets.mask.enabled:
            masks[nets.mask.set_name] = simulate_mask(
                visible,
                nets.mask.segmenter,
                self.scenario.rng(SEGMENTER_STREAM, k),
                visible_fraction=vis,
            )
        return DatasetFrame(
            k=k,
            t_s=current.t_s,
            rgb=current.rgb,
            depth_m=current.sensor_depth_m,
            T_world_cam=current.T_world_cam,
            gt_T_cam_obj=current.T_cam_obj,
            gt_v_obj_mps=current.v_obj_mps,
            gt_w_radps=current.w_radps,
            gt_mask=visible,
            gt_mask_full=full,
            flows=flows,
            detector_masks=masks,
            detector_poses=poses,
            gt_visible_fraction=vis,
            gt_distractors=(
                self._distractor_truths(current) if distractors is None else distractors
            ),
        )

    def _distractor_truths(self, frame: RenderedFrame) -> tuple[DistractorTruth, ...]:
        """Each distractor's pose, visible mask (its body in the rendered segmentation) and full
        silhouette (rendered alone, united with the visible mask)."""
        assert frame.body_index is not None
        truths = []
        for i, (name, T) in enumerate(
            zip(frame.distractor_names, frame.T_cam_distractors, strict=True)
        ):
            visible = frame.body_index == frame.body_names.index(f"distractor{i}")
            full = self._distractor_silhouettes[i].render_silhouette(T, self.scenario.intrinsics)
            truths.append(
                DistractorTruth(name=name, T_cam_obj=T, mask=visible, mask_full=full | visible)
            )
        return tuple(truths)

    def _full_silhouette(self, frame: RenderedFrame) -> Bool:
        assert self._silhouettes is not None
        return self._silhouettes.render_silhouette(frame.T_cam_obj, self.scenario.intrinsics)

    def _pose_detection(self, k: int, vis_k: float) -> F64 | None:
        """Frame k's detection: the estimator over the whole track, frame k's visible fraction
        (the other frames' values do not change frame k's result; tests/generation checks).

        The track's sample with every frame fully visible is the same for every frame whose
        object is fully visible (the same inputs), so it is computed once and kept: the
        estimator's O(N) work then runs only for partly visible frames."""
        if vis_k == 1.0:
            if self._unoccluded_detections is None:
                self._unoccluded_detections = self._pose_sample(np.ones(self.n_frames))
            valid, T_cam_obj = self._unoccluded_detections
        else:
            vis = np.ones(self.n_frames)
            vis[k] = vis_k
            valid, T_cam_obj = self._pose_sample(vis)
        return T_cam_obj[k].copy() if valid[k] else None

    def _pose_sample(self, visible_fraction: F64) -> tuple[Bool, F64]:
        """(N,) valid flags and (N, 4, 4) detected ``T_cam_obj`` [m] of the pose estimator
        over the whole track with the given (N,) visible fractions."""
        sample = sample_pose_detections(
            self.track,
            self.networks.pose.estimator_for(self.scenario.object.name_or_path),
            self.scenario.rng(POSE_ESTIMATOR_STREAM),
            visible_fraction=visible_fraction,
        )
        return np.asarray(sample.valid, dtype=bool), np.asarray(sample.T_cam_obj)

    # ---------------------------------------------------------------------------- lifetime
    def close(self) -> None:
        """Frees the OpenGL contexts (idempotent)."""
        if self._silhouettes is not None:
            self._silhouettes.close()
            self._silhouettes = None
        for renderer in self._distractor_silhouettes:
            renderer.close()
        self._distractor_silhouettes = []
        self._renderer.close()

    def __enter__(self) -> SequenceGenerator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
