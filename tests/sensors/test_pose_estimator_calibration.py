"""The DOPE-like defaults reproduce the paper's "DOPE (ideal)" row (Table IV) on Fast-YCB-like
motions of the six objects, scored as the reference scores it (every detected frame, no delay,
misses left out, ADD with all model points, "ALL" pools the frames).

Calibration set-up (docs/sensors.md): each of the six Fast-YCB objects, as the asset
registry's procedural stand-in (the real YCB sizes, NVDU-aligned frame, 2620 model points like
the YCB-Video ``points.xyz``; no external data needed), moves for ``FRAMES_PER_OBJECT`` frames at
30 fps along a smooth random path 0.5-0.8 m from the camera, turning about a random orientation
per object (speeds up to ~0.65 m/s and ~280 deg/s, the paper's "up to 63 cm/s and 266 deg/s").
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from roft_sim.assets.objects import load_object
from roft_sim.assets.registry import FAST_YCB_OBJECTS
from roft_sim.geometry import matrix_from_rotvec, transform_from_rt
from roft_sim.metrics import evaluate_sequence, pool_metrics
from roft_sim.records import PoseTrack
from roft_sim.sensors.pose_estimator import PoseEstimatorConfig, sample_pose_detections

TARGET = {"add_auc_pct": 84.94, "rmse_t_cm": 8.7, "rmse_a_deg": 16.277}
"""ROFT paper, Table IV, "DOPE [23] (ideal)"."""
TOLERANCE = {"add_auc_pct": 0.5, "rmse_t_cm": 0.6, "rmse_a_deg": 0.8}
"""Accepted |reached - target|. Over 8 seeds at this length the defaults gave mean 84.89 %,
8.75 cm, 16.31 deg with per-run standard deviations 0.10 %, 0.17 cm, 0.23 deg, so each
tolerance is 3.5 to 5 standard deviations (docs/sensors.md)."""
FRAMES_PER_OBJECT = 10000
OBJECTS = FAST_YCB_OBJECTS


def model_points(name: str, assets_dir: Path | None = None) -> np.ndarray:
    """(2620, 3) model points [m]: the registry's procedural stand-in, or the real mesh when
    ``assets_dir`` holds it."""
    prefer = "procedural" if assets_dir is None else "ycb"
    return load_object(name, assets_dir=assets_dir, prefer=prefer).model.model_points_m


def fast_ycb_like_track(rng, n: int, fps: int = 30) -> PoseTrack:
    """A smooth random 6-D path: sums of sinusoids, 0.5-0.8 m away, about a random orientation."""
    t = np.arange(n) / fps
    f = rng.uniform(0.1, 0.9, (2, 3, 3))  # [position/rotation, axis, component] Hz
    ph = rng.uniform(0, 2 * np.pi, (2, 3, 3))
    amp_p = np.array([0.05, 0.04, 0.05])  # per sinusoid, per axis [m]
    pos = np.array([0.0, 0.02, 0.65]) + np.einsum(
        "j,nij->ni",
        np.ones(3),
        amp_p[:, None] * np.sin(2 * np.pi * f[0] * t[:, None, None] + ph[0]),
    )
    rotvec = rng.normal(0, 1.0, 3) + np.einsum(
        "nij->ni", 0.35 * np.sin(2 * np.pi * f[1] * t[:, None, None] + ph[1])
    )
    T = transform_from_rt(matrix_from_rotvec(rotvec), pos)
    v = np.gradient(pos, t, axis=0)
    return PoseTrack(t_s=t, T_cam_obj=T, v_obj_mps=v, w_radps=np.zeros((n, 3)))


def dope_ideal_metrics(
    config: PoseEstimatorConfig,
    seed: int,
    frames: int = FRAMES_PER_OBJECT,
    assets_dir: Path | None = None,
):
    """Pooled "ALL" metrics of the simulated detector over the six objects."""
    ss = np.random.SeedSequence(seed)
    per_object = {}
    for name, child in zip(OBJECTS, ss.spawn(len(OBJECTS)), strict=True):
        track_rng, det_rng = (np.random.default_rng(s) for s in child.spawn(2))
        gt = fast_ycb_like_track(track_rng, frames)
        det = sample_pose_detections(gt, config, det_rng)
        per_object[name] = evaluate_sequence(
            det.T_cam_obj,
            gt.T_cam_obj,
            model_points(name, assets_dir),
            valid=det.valid,
            invalid="exclude",
        )
    return pool_metrics(per_object)


def test_track_covers_the_fast_ycb_range():
    gt = fast_ycb_like_track(np.random.default_rng(0), 3000)
    z = gt.T_cam_obj[:, 2, 3]
    speed = np.linalg.norm(gt.v_obj_mps, axis=1)
    assert z.min() > 0.45 and z.max() < 0.85
    assert 0.3 < speed.max() < 1.0


def _check_against_target(pooled, label: str) -> None:
    reached = {k: getattr(pooled, k) for k in TARGET}
    print(f"DOPE (ideal), {label}:", {k: round(v, 3) for k, v in reached.items()})
    for key, target in TARGET.items():
        assert abs(reached[key] - target) <= TOLERANCE[key], (key, reached[key], target)
    assert pooled.frames > 0.97 * 6 * FRAMES_PER_OBJECT  # misses (2 %) are left out


@pytest.mark.slow
def test_defaults_reproduce_dope_ideal_row():
    _check_against_target(dope_ideal_metrics(PoseEstimatorConfig(), seed=2022)["ALL"], "stand-ins")


@pytest.mark.slow
@pytest.mark.shared_data
def test_defaults_reproduce_dope_ideal_row_with_real_meshes(shared_ycb_dir):
    pooled = dope_ideal_metrics(PoseEstimatorConfig(), seed=2022, assets_dir=shared_ycb_dir)
    _check_against_target(pooled["ALL"], "real YCB meshes")
