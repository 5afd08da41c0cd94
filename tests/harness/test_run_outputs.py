"""The files `roft-sim run` writes: formats, round trips, metrics.json, run.json."""

from __future__ import annotations

import json

import numpy as np
import pytest
from harness_cases import ECHO_SPEC, POSE_MISSES, box_sequence

from roft_sim.faults import load_faults
from roft_sim.geometry.se3 import v_o_from_v_obj
from roft_sim.harness import RunOptions, SequenceSource, run_sequences
from roft_sim.harness.outputs import (
    load_deliveries,
    load_estimates,
    load_frame_errors,
    read_pose_estimate,
    read_velocity_estimate,
)
from roft_sim.metrics import evaluate_estimates, pool_metrics
from roft_sim.testing.analytic_scene import AnalyticBoxDepthRenderer

REQUIRED = ("add_auc_pct", "rmse_t_cm", "rmse_a_deg", "rmse_v_cmps", "rmse_w_dps", "frames")


@pytest.fixture(scope="module")
def sequences():
    return [box_sequence(name="box_a", seed=1), box_sequence(name="box_b", seed=2, n_frames=18)]


@pytest.fixture(scope="module")
def echo_run(sequences, tmp_path_factory):
    out = tmp_path_factory.mktemp("echo")
    # the detector misses frames 5 and 11 but the echo holds: every frame has an estimate
    options = RunOptions(tracker="echo", flow="stored:gt", faults=load_faults("none"))
    sources = [SequenceSource(sequence=s) for s in sequences]
    return run_sequences(sources, options, out, spec=ECHO_SPEC), out


@pytest.fixture(scope="module")
def roft_run(sequences, tmp_path_factory):
    out = tmp_path_factory.mktemp("roft")
    options = RunOptions(tracker="roft", flow="stored:gt")
    sources = [SequenceSource(sequence=s) for s in sequences]
    result = run_sequences(
        sources, options, out, depth_renderer_factory=lambda m: AnalyticBoxDepthRenderer()
    )
    return result, out


def test_files_per_sequence(echo_run):
    result, out = echo_run
    assert sorted(p.name for p in out.iterdir()) == ["box_a", "box_b", "metrics.json", "run.json"]
    for name in ("box_a", "box_b"):
        files = sorted(p.name for p in (out / name).iterdir())
        assert files == [
            "deliveries.npz",
            "estimates.npz",
            "execution_times.txt",
            "frame_errors.npz",
            "metrics.json",
            "pose_estimate.txt",
            "velocity_estimate.txt",
        ]


def test_pose_estimate_has_13_columns_and_reads_back(echo_run):
    result, out = echo_run
    run = result.runs[0]
    text = (out / "box_a" / "pose_estimate.txt").read_text().splitlines()
    assert len(text) == len(run.estimates)
    assert {len(line.split()) for line in text} == {13}
    T, v, w, valid = read_pose_estimate(out / "box_a" / "pose_estimate.txt")
    for k, e in enumerate(run.estimates):
        assert valid[k] == e.valid
        if e.valid:
            np.testing.assert_allclose(T[k], e.T_cam_obj, atol=1e-12)
            np.testing.assert_array_equal(v[k], e.v_obj_mps)
            np.testing.assert_array_equal(w[k], e.w_radps)
        else:
            assert text[k].split() == ["0"] * 13


def test_invalid_frames_are_rows_of_zeros(sequences, tmp_path):
    options = RunOptions(tracker="echo", flow="none", faults=load_faults("paper"))
    # no pose set: never a pose, every frame invalid
    result = run_sequences(
        [SequenceSource(sequence=sequences[0])],
        options.replace(poses="none"),
        tmp_path,
        spec=ECHO_SPEC,
    )
    rows = (tmp_path / "box_a" / "pose_estimate.txt").read_text().splitlines()
    assert set(rows) == {" ".join(["0"] * 13)}
    assert result.metrics["box_a"]["frames_invalid"] == len(rows)
    assert result.metrics["box_a"]["add_auc_pct"] == 0.0


def test_velocity_estimate_gives_the_estimate_back_under_the_reference_conversion(echo_run):
    """Without a spatial twist, v_o = v_obj - w x t_gt, so that the reference's
    ``v = v_o + w x t_gt`` (evaluate.py, with the GROUND-TRUTH position) yields v_obj."""
    result, out = echo_run
    rows = read_velocity_estimate(out / "box_a" / "velocity_estimate.txt")
    run = result.runs[0]
    assert rows.shape == (len(run.estimates), 6)
    t_gt = run.ground_truth.T_cam_obj[:, :3, 3]
    for k, e in enumerate(run.estimates):
        if not e.valid:
            np.testing.assert_array_equal(rows[k], 0.0)
            continue
        reference_v = rows[k, :3] + np.cross(rows[k, 3:], t_gt[k])
        np.testing.assert_allclose(reference_v, e.v_obj_mps, atol=1e-15)
        np.testing.assert_allclose(rows[k, :3], v_o_from_v_obj(e.v_obj_mps, e.w_radps, t_gt[k]))
        np.testing.assert_array_equal(rows[k, 3:], e.w_radps)
        # and not with the estimate's own position (they differ: the detector is offset)
        own = v_o_from_v_obj(e.v_obj_mps, e.w_radps, e.T_cam_obj[:3, 3])
        assert np.abs(rows[k, :3] - own).max() > 1e-5


def test_velocity_estimate_is_the_spatial_twist_when_reported(roft_run):
    result, out = roft_run
    rows = read_velocity_estimate(out / "box_a" / "velocity_estimate.txt")
    estimates = result.runs[0].estimates
    # frame 0 has no flow, so ROFT claims no twist there; the file then holds the pose
    # filter's velocity (v_o at the estimated position) or zeros, as the reference's 0
    assert estimates[0].spatial_twist is None
    e = estimates[0]
    expected = np.zeros(6)
    if e.valid:
        expected = np.r_[v_o_from_v_obj(e.v_obj_mps, e.w_radps, e.T_cam_obj[:3, 3]), e.w_radps]
    np.testing.assert_allclose(rows[0], expected, rtol=0, atol=1e-12)
    twists = np.array([e.spatial_twist for e in estimates[1:]])
    np.testing.assert_allclose(rows[1:], twists, rtol=0, atol=0)


def test_estimates_npz_round_trips_every_field(roft_run):
    result, out = roft_run
    loaded = load_estimates(out / "box_a" / "estimates.npz")
    original = result.runs[0].estimates
    assert len(loaded) == len(original)
    for a, b in zip(loaded, original, strict=True):
        assert a.k == b.k and a.valid == b.valid
        np.testing.assert_array_equal(a.T_cam_obj, b.T_cam_obj)
        np.testing.assert_array_equal(a.v_obj_mps, b.v_obj_mps)
        np.testing.assert_array_equal(a.w_radps, b.w_radps)
        np.testing.assert_array_equal(a.covariance, b.covariance)
        np.testing.assert_array_equal(a.spatial_twist, b.spatial_twist)
        assert a.accepted_pose_ids == b.accepted_pose_ids
        assert a.rejected_pose_ids == b.rejected_pose_ids
        assert a.dropped_pose_ids == b.dropped_pose_ids
        assert dict(a.diagnostics) == dict(b.diagnostics)


def test_deliveries_npz_matches_the_ledger(roft_run):
    result, out = roft_run
    pose = load_deliveries(out / "box_a" / "deliveries.npz")["pose"]
    events = result.runs[0].pose_deliveries
    assert pose.arrival_k.tolist() == [e.arrival_k for e in events]
    assert pose.true_capture_k.tolist() == [e.true_capture_k for e in events]
    assert pose.latest_arrived(13) == 1 and pose.latest_arrived(-1) is None


def test_metrics_json_has_all_mean_and_every_sequence(echo_run, sequences):
    result, out = echo_run
    metrics = json.loads((out / "metrics.json").read_text())
    assert list(metrics) == ["ALL", "MEAN", "box_a", "box_b"]
    for name, entry in metrics.items():
        for key in REQUIRED:
            assert key in entry, (name, key)
    assert metrics["ALL"]["frames"] == 24 + 18
    assert "time_median_ms" in metrics["box_a"] and "sync" in metrics["box_a"]
    assert metrics["box_a"]["faults"]["pose"]["runs"] == 24
    # an independent path: the metric functions on the in-memory estimates
    independent = pool_metrics(
        {
            run.sequence_name: evaluate_estimates(
                run.estimates, seq.ground_truth(), seq.object_model().model_points_m
            )
            for run, seq in zip(result.runs, sequences, strict=True)
        }
    )
    for name in ("ALL", "MEAN", "box_a", "box_b"):
        for key in ("add_auc_pct", "rmse_t_cm", "rmse_a_deg", "rmse_v_cmps", "rmse_w_dps"):
            assert metrics[name][key] == pytest.approx(getattr(independent[name], key), rel=1e-12)


def test_frame_errors_round_trip(echo_run):
    result, out = echo_run
    loaded = load_frame_errors(out / "box_a" / "frame_errors.npz")
    original = result.pooled["box_a"]
    assert loaded.summary() | {"time_median_ms": 0} == original.summary() | {"time_median_ms": 0}
    np.testing.assert_array_equal(loaded.add_m, original.add_m)
    np.testing.assert_array_equal(loaded.t_err_cm, original.t_err_cm)


def test_run_json_records_configuration_seeds_and_versions(echo_run):
    _, out = echo_run
    run = json.loads((out / "run.json").read_text())
    assert run["kind"] == "run"
    assert run["tracker"]["name"] == "echo"
    assert run["options"]["faults"]["name"] == "none"
    assert run["options"]["tracker_config"] == {"draw_noise": False}
    seq = run["sequences"][0]
    assert seq["name"] == "box_a" and seq["frames"] == 24
    assert seq["seeds"]["seed"] == 0 and seq["seeds"]["children"] == ["tracker", "stream", "flow"]
    assert seq["inputs"] == {"poses": "dope", "masks": "mrcnn", "flow": "stored:gt"}
    assert {"python", "numpy", "opencv", "roft-sim"} <= set(run["versions"])


def test_a_pose_miss_shows_in_the_ledger_summary(echo_run):
    result, _ = echo_run
    fates = result.metrics["box_a"]["faults"]["pose"]["fates"]
    assert fates["missed"] == len(POSE_MISSES)
