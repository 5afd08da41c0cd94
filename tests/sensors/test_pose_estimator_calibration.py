"""The DOPE-like defaults reproduce the paper's "DOPE (ideal)" row (Table IV) on Fast-YCB-like
motions of the six objects, scored as the reference scores it (every detected frame, no delay,
misses left out, ADD with all model points, "ALL" pools the frames).

Calibration set-up (docs/sensors.md): for each of the six Fast-YCB objects, a procedural
stand-in of its measured size (boxes, a cylinder, an elliptic cylinder; 2620 surface points like
the YCB-Video ``points.xyz``) moves for ``FRAMES_PER_OBJECT`` frames at 30 fps along a smooth
random path 0.5-0.8 m from the camera, turning about a random orientation per object (speeds up
to ~0.65 m/s and ~280 deg/s, the paper's "up to 63 cm/s and 266 deg/s").
"""

from __future__ import annotations

import numpy as np
import pytest

from roft_sim.geometry import matrix_from_rotvec, transform_from_rt
from roft_sim.metrics import evaluate_sequence, pool_metrics
from roft_sim.records import PoseTrack
from roft_sim.sensors.pose_estimator import PoseEstimatorConfig, sample_pose_detections

TARGET = {"add_auc_pct": 84.94, "rmse_t_cm": 8.7, "rmse_a_deg": 16.277}
"""ROFT paper, Table IV, "DOPE [23] (ideal)"."""
TOLERANCE = {"add_auc_pct": 0.5, "rmse_t_cm": 0.6, "rmse_a_deg": 0.8}
"""Accepted |reached - target|. Over 8 seeds at this length the defaults gave mean 84.94 %,
8.75 cm, 16.30 deg with per-run standard deviations 0.105 %, 0.168 cm, 0.236 deg, so each
tolerance is 3.5 to 5 standard deviations (docs/sensors.md)."""
FRAMES_PER_OBJECT = 10000
SHAPES = {
    "003_cracker_box": ("box", (0.0718, 0.164, 0.2134)),
    "004_sugar_box": ("box", (0.0495, 0.0942, 0.176)),
    "005_tomato_soup_can": ("cylinder", (0.0679, 0.0677, 0.1019)),
    "006_mustard_bottle": ("cylinder", (0.0972, 0.0666, 0.1913)),
    "009_gelatin_box": ("box", (0.0894, 0.1011, 0.0301)),
    "010_potted_meat_can": ("box", (0.1021, 0.0601, 0.0835)),
}
"""Extents [m] measured on the YCB google_16k meshes (x, y, z of the stand-in)."""


def stand_in_points(kind: str, extents_m: tuple[float, float, float], rng, m: int = 2620):
    """(m, 3) points uniform by area on a box or an elliptic cylinder centred at the origin."""
    a, b, c = (e / 2 for e in extents_m)
    if kind == "box":
        areas = np.array([b * c, b * c, a * c, a * c, a * b, a * b])
        face = rng.choice(6, m, p=areas / areas.sum())
        p = rng.uniform(-1, 1, (m, 3)) * [a, b, c]
        axis = face // 2
        p[np.arange(m), axis] = np.where(face % 2, 1, -1) * np.array([a, b, c])[axis]
        return p
    side = np.pi * (a + b) * 2 * c  # approx. lateral area of the elliptic cylinder
    caps = 2 * np.pi * a * b
    on_side = rng.random(m) < side / (side + caps)
    phi = rng.uniform(0, 2 * np.pi, m)
    rad = np.where(on_side, 1.0, np.sqrt(rng.random(m)))
    z = np.where(on_side, rng.uniform(-c, c, m), np.where(rng.random(m) < 0.5, -c, c))
    return np.stack([a * rad * np.cos(phi), b * rad * np.sin(phi), z], 1)


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


def dope_ideal_metrics(config: PoseEstimatorConfig, seed: int, frames: int = FRAMES_PER_OBJECT):
    """Pooled "ALL" metrics of the simulated detector over the six stand-ins."""
    ss = np.random.SeedSequence(seed)
    per_object = {}
    for (name, (kind, ext)), child in zip(SHAPES.items(), ss.spawn(len(SHAPES)), strict=True):
        geo_rng, det_rng = (np.random.default_rng(s) for s in child.spawn(2))
        pts = stand_in_points(kind, ext, geo_rng)
        gt = fast_ycb_like_track(geo_rng, frames)
        det = sample_pose_detections(gt, config, det_rng)
        per_object[name] = evaluate_sequence(
            det.T_cam_obj, gt.T_cam_obj, pts, valid=det.valid, invalid="exclude"
        )
    return pool_metrics(per_object)


def test_track_covers_the_fast_ycb_range():
    gt = fast_ycb_like_track(np.random.default_rng(0), 3000)
    z = gt.T_cam_obj[:, 2, 3]
    speed = np.linalg.norm(gt.v_obj_mps, axis=1)
    assert z.min() > 0.45 and z.max() < 0.85
    assert 0.3 < speed.max() < 1.0


@pytest.mark.slow
def test_defaults_reproduce_dope_ideal_row():
    pooled = dope_ideal_metrics(PoseEstimatorConfig(), seed=2022)["ALL"]
    reached = {k: getattr(pooled, k) for k in TARGET}
    print("DOPE (ideal) reached:", {k: round(v, 3) for k, v in reached.items()})
    for key, target in TARGET.items():
        assert abs(reached[key] - target) <= TOLERANCE[key], (key, reached[key], target)
    assert pooled.frames > 0.97 * 6 * FRAMES_PER_OBJECT  # misses (2 %) are left out
