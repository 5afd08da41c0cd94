"""`roft-sim report` on run and sweep folders."""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from roft_sim.cli import main

# the hand-made sequences live with the harness tests
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "harness"))
from harness_cases import write_box_dataset  # noqa: E402


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    root = tmp_path_factory.mktemp("report")
    dataset = write_box_dataset(root / "data", names=("box_a",), width=96, height=72)
    out = root / "run"
    args = ["run", str(dataset), "--tracker", "detector-hold", "--faults", "outliers-10pct"]
    assert main([*args, "--flow", "none", "--out", str(out)]) == 0
    return out


def _frames(path: Path) -> list:
    capture = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, frame = capture.read()
        if not ok:
            return frames
        frames.append(frame)


def test_run_report_has_tables_plots_video_and_stills(run_dir, capsys):
    assert main(["report", str(run_dir)]) == 0
    report = run_dir / "report"
    assert capsys.readouterr().out.strip() == str(report / "report.md")
    text = (report / "report.md").read_text()
    assert "# Report: detector-hold on 1 sequence(s)" in text
    assert "| box_a |" in text and "| ALL |" in text and "| MEAN |" in text
    assert "outliers-10pct" in text
    for name in (
        "plots/box_a_errors.png",
        "plots/box_a_accuracy.png",
        "plots/box_a_velocity.png",
    ):
        assert f"]({name})" in text
        image = cv2.imread(str(report / name))
        assert image is not None and image.shape[0] >= 300
    frames = _frames(report / "videos" / "box_a_overlay.mp4")
    assert len(frames) == 24 and frames[0].shape == (72, 96, 3)
    stills = sorted((report / "stills").glob("box_a_k*.png"))
    assert stills and all(f"]({p.relative_to(report).as_posix()})" in text for p in stills)


def test_report_options_and_json(run_dir, tmp_path, capsys):
    out = tmp_path / "r"
    args = ["report", str(run_dir), "--out", str(out), "--max-video-frames", "5"]
    assert main([*args, "--video-scale", "2", "--json"]) == 0
    files = [Path(p) for p in __import__("json").loads(capsys.readouterr().out)["files"]]
    video = next(p for p in files if p.suffix == ".mp4")
    frames = _frames(video)
    assert len(frames) == 5 and frames[0].shape == (144, 192, 3)
    assert main(["report", str(run_dir), "--out", str(tmp_path / "n"), "--no-video"]) == 0
    assert not (tmp_path / "n" / "videos").exists()


def test_report_without_the_dataset_notes_it(run_dir, tmp_path, capsys):
    import json
    import shutil

    moved = tmp_path / "run"
    shutil.copytree(run_dir, moved)
    record = json.loads((moved / "run.json").read_text())
    record["sequences"][0]["path"] = str(tmp_path / "gone")
    (moved / "run.json").write_text(json.dumps(record))
    assert main(["report", str(moved)]) == 0
    text = (moved / "report" / "report.md").read_text()
    assert "## Notes" in text and "is not available" in text


def test_sweep_report(tmp_path, capsys):
    dataset = write_box_dataset(tmp_path / "data", names=("box_a",))
    sweep = tmp_path / "sweep"
    args = ["sweep", str(dataset), "--trackers", "detector-hold", "--flow", "none"]
    assert main([*args, "--param", "dropout=0,0.5", "--out", str(sweep), "--no-plots"]) == 0
    capsys.readouterr()
    assert main(["report", str(sweep)]) == 0
    report = sweep / "report"
    text = (report / "report.md").read_text()
    assert "| detector-hold | paper | 0.5 |" in text
    assert (report / "plots" / "error_vs_dropout.png").is_file()


def test_report_of_a_folder_that_is_no_result(tmp_path, capsys):
    assert main(["report", str(tmp_path)]) == 2
    assert "is not a results folder" in capsys.readouterr().err
    (tmp_path / "paper.json").write_text("{}")
    assert main(["report", str(tmp_path)]) == 2
    assert "its report is tables.md" in capsys.readouterr().err
    assert main(["report", str(tmp_path / "none")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_report_of_an_unknown_sequence_is_a_usage_error(run_dir, tmp_path, capsys):
    out = tmp_path / "r"
    code = main(["report", str(run_dir), "--out", str(out), "--no-video", "--sequence", "box_z"])
    assert code == 2
    assert "no sequence 'box_z'" in capsys.readouterr().err
    assert not (out / "report.md").exists()


def test_report_out_that_is_a_file_is_a_usage_error(run_dir, tmp_path, capsys):
    """Review regression: --out FILE used to end in a NotADirectoryError traceback."""
    afile = tmp_path / "report.md"
    afile.write_text("kept")
    assert main(["report", str(run_dir), "--out", str(afile), "--no-video"]) == 2
    assert f"--out {str(afile)!r} is a file" in capsys.readouterr().err
    assert main(["report", str(run_dir), "--out", str(afile / "sub"), "--no-video"]) == 2
    assert f"lies under {str(afile)!r}, which is a file" in capsys.readouterr().err
    assert afile.read_text() == "kept"


def test_the_overlay_keeps_the_newest_mask_when_an_older_one_arrives_late():
    """Review regression: under reordering a mask of an earlier capture frame used to replace
    the newer one shown, while the report says it shows the newest mask received."""
    from roft_sim.harness.report_builder import newest_mask
    from roft_sim.records import MaskDetection

    def mask(capture_k: int, arrival_k: int) -> MaskDetection:
        return MaskDetection(
            capture_k=capture_k, arrival_k=arrival_k, mask=np.zeros((2, 2), bool),
            detection_id=capture_k,
        )  # fmt: skip

    assert newest_mask(None, ()) is None
    m12, m6, m18 = mask(12, 18), mask(6, 19), mask(18, 20)
    assert newest_mask(None, (m6, m12)) is m12
    assert newest_mask(m12, (m6,)) is m12  # the late, older mask does not replace it
    assert newest_mask(m12, (m6, m18)) is m18
