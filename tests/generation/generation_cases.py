"""Shared helpers of the generation tests (imported as ``from generation_cases import ...``).

- :func:`tiny_scenario`: a shipped CI scenario made tiny (few frames, small images).
- :func:`run_generate`: :func:`roft_sim.generation.generate_dataset` without a progress bar.
- :func:`tree_hashes`: SHA-256 of every file under a folder (byte-identity checks).
- :func:`render_oracle`: an independent in-process render of the same frames (SceneRenderer,
  ground_truth_flow, the NVOF error model applied to that flow with the set's seed, the
  silhouette renderer).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from roft_sim.generation import (
    GenerationOptions,
    ScenarioOverrides,
    generate_dataset,
    shipped_scenarios_dir,
)
from roft_sim.scenario import Scenario, load_scenario

TINY = (160, 120)
"""Resolution of the default-suite generation tests [px]: the segmenter's 100-px minimum is
still met by the CI objects."""


def tiny_scenario(
    name: str = "mustard_hand_moving_camera", *, frames: int = 4, resolution=TINY
) -> Scenario:
    """A CI scenario (``scenarios/ci/<name>.toml``) with ``frames`` frames at ``resolution``."""
    scenario = load_scenario(shipped_scenarios_dir() / "ci" / f"{name}.toml")
    return ScenarioOverrides(frames=frames, resolution=resolution).apply(scenario)


def run_generate(scenarios, out: Path, **options):
    """Generates ``scenarios`` into ``out`` (no progress bar, no asset cache)."""
    options.setdefault("progress", False)
    overrides = options.pop("overrides", None)
    return generate_dataset(list(scenarios), out, GenerationOptions(**options), overrides=overrides)


def tree_hashes(root: Path) -> dict[str, str]:
    """Relative path -> SHA-256 of every file under ``root``."""
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


@dataclass
class OracleFrames:
    """What an independent in-process render gives for frames 0..N-1."""

    frames: list
    """RenderedFrame per frame."""
    full_masks: list
    """(H, W) bool full silhouettes (object alone), united with the visible mask."""
    gt_flows: list
    """FlowField F_k (None for k = 0)."""
    nvof_flows: list
    """The ``nvof_1_slow`` set's FlowField F_k (``nvof-model``; None for k = 0)."""
    model_mesh: object
    """The rendered object's mesh."""


def render_oracle(scenario: Scenario) -> OracleFrames:
    """Renders every frame of ``scenario`` directly (see the module doc)."""
    from roft_sim.generation.sequence_generator import flow_set_seed
    from roft_sim.records import FlowField
    from roft_sim.render import MujocoDepthRenderer, SceneRenderer, ground_truth_flow
    from roft_sim.sensors.flow_sources import frame_rng
    from roft_sim.sensors.nvof_error_model import NvofErrorModelConfig, nvof_error_model

    with SceneRenderer(scenario) as r:
        frames = [r.render_frame(k) for k in range(scenario.n_frames)]
        mesh = r.object_assets.mesh
    with MujocoDepthRenderer(mesh) as d:
        full = [
            (d.render_depth(f.T_cam_obj, scenario.intrinsics)[0] > 0) | f.object_mask
            for f in frames
        ]
    gt_flows = [None] + [
        ground_truth_flow(a, b, scenario.intrinsics)
        for a, b in zip(frames[:-1], frames[1:], strict=True)
    ]
    h, w = scenario.intrinsics.shape
    seed = flow_set_seed(scenario, "nvof_1_slow")
    nvof_flows: list[FlowField | None] = [None]
    for k in range(1, len(frames)):
        flow, valid = nvof_error_model(
            gt_flows[k].dense(h, w), NvofErrorModelConfig(), frame_rng(seed, k - 1, k)
        )
        nvof_flows.append(FlowField(flow_px=flow, from_k=k - 1, to_k=k, grid_px=4, valid=valid))
    return OracleFrames(
        frames=frames,
        full_masks=full,
        gt_flows=gt_flows,
        nvof_flows=nvof_flows,
        model_mesh=mesh,
    )


def visible_fractions(visible_masks, full_masks) -> np.ndarray:
    """(N,) |visible| / |visible or full| per frame (0 for empty)."""
    out = []
    for v, f in zip(visible_masks, full_masks, strict=True):
        area = np.count_nonzero(v | f)
        out.append(0.0 if area == 0 else np.count_nonzero(v) / area)
    return np.array(out)
