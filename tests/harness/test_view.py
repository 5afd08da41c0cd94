"""`roft-sim view`: a Rerun recording of a run, read back with rerun's chunk reader."""

from __future__ import annotations

import json

import numpy as np
import pytest
from harness_cases import write_box_dataset

from roft_sim.cli import main
from roft_sim.cli.view import has_display
from roft_sim.harness.outputs import load_deliveries, load_estimates, load_frame_errors

rerun_chunk = pytest.importorskip("rerun.chunk", reason="rerun-sdk is not installed ('.[view]')")


def _columns(chunks, entity: str, column: str) -> tuple[list[int], list]:
    """(frames, values) of ``column`` at ``entity`` over every chunk, in frame order."""
    rows = []
    for chunk in chunks:
        if chunk.entity_path != entity or chunk.is_static:
            continue
        data = chunk.to_record_batch().to_pydict()
        if column in data:
            rows += [(f, v) for f, v in zip(data["frame"], data[column], strict=True) if v]
    rows.sort(key=lambda r: r[0])
    return [r[0] for r in rows], [r[1] for r in rows]


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    root = tmp_path_factory.mktemp("view")
    data = write_box_dataset(root / "data", names=("box_a",))
    out = root / "run"
    args = ["run", str(data), "--tracker", "detector-hold", "--flow", "none", "--out", str(out)]
    assert main([*args, "--invalid", "failure", "--no-progress"]) == 0
    return out


def test_the_recording_holds_the_run(run_dir, tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    rrd = tmp_path / "box.rrd"
    assert main(["view", str(run_dir), "--out", str(rrd), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["file"] == str(rrd) and summary["sequences"] == ["box_a"]
    assert summary["opened"] is False and summary["frames"] == 24
    chunks = rerun_chunk.RrdReader(rrd).stream().to_chunks()
    paths = {c.entity_path for c in chunks}
    for entity in (
        "camera",
        "camera/rgb",
        "camera/depth",
        "camera/mask_gt",
        "camera/mask_delivered",
        "camera/flow",
        "gt",
        "gt/points",
        "estimate",
        "estimate/points",
        "detection",
        "delay/pose",
        "delay/mask",
        *(f"errors/{s}" for s in ("t_cm", "a_deg", "v_cmps", "w_dps", "add_cm")),
    ):
        assert f"/box_a/{entity}" in paths, entity
    frames, _ = _columns(chunks, "/box_a/camera/rgb", "Image:buffer")
    assert frames == list(range(24))
    # the error series are the run's per-frame errors
    errors = load_frame_errors(run_dir / "box_a" / "frame_errors.npz")
    frames, values = _columns(chunks, "/box_a/errors/t_cm", "Scalars:scalars")
    scored = np.isfinite(errors.t_err_norm_cm)
    assert frames == errors.frame_index[scored].tolist()
    np.testing.assert_allclose(np.concatenate(values), errors.t_err_norm_cm[scored], rtol=1e-15)
    # every pose delivery with its delay, as the run's ledger recorded it
    deliveries = load_deliveries(run_dir / "box_a" / "deliveries.npz")["pose"]
    frames, values = _columns(chunks, "/box_a/delay/pose", "Scalars:scalars")
    assert frames == sorted(deliveries.arrival_k.tolist())
    delays = deliveries.arrival_k - deliveries.true_capture_k
    expected = sorted(zip(deliveries.arrival_k, delays, strict=True))
    assert np.concatenate(values).tolist() == [float(d) for _, d in expected]
    # estimated poses as 3D frames: the translation of each valid estimate
    estimates = load_estimates(run_dir / "box_a" / "estimates.npz")
    frames, values = _columns(chunks, "/box_a/estimate", "Transform3D:translation")
    assert frames == [e.k for e in estimates if e.valid]
    np.testing.assert_allclose(
        np.array(values).reshape(-1, 3),
        np.array([e.T_cam_obj[:3, 3] for e in estimates if e.valid]),
        rtol=1e-6,  # rerun stores float32
    )


def test_without_a_display_it_says_where_the_file_is(run_dir, capsys, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["view", str(run_dir), "--max-frames", "2"]) == 0
    out = capsys.readouterr().out
    assert f"open it with: rerun {run_dir / 'run.rrd'}" in out
    assert (run_dir / "run.rrd").is_file()
    assert has_display({"DISPLAY": ":0"}) and not has_display({})


def test_not_a_run_folder_is_a_usage_error(tmp_path, capsys):
    assert main(["view", str(tmp_path), "--no-open"]) == 2
    assert "not a roft-sim run folder" in capsys.readouterr().err
