"""Preview videos: colour coding, video files OpenCV can read back, and the CLI verb."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from stand_ins import open_renderer, small_scenario

from roft_sim.cli import main
from roft_sim.errors import ConfigError
from roft_sim.records import FlowField
from roft_sim.render.preview import depth_to_rgb, flow_to_rgb, write_preview
from roft_sim.report.video import VideoWriter

REPO = Path(__file__).resolve().parents[2]


def test_flow_colours_encode_direction_and_magnitude():
    flow = np.zeros((1, 4, 2), np.float32)
    flow[0, 0] = (2.0, 0.0)  # right: red
    flow[0, 1] = (-2.0, 0.0)  # left: cyan
    flow[0, 2] = (0.5, 0.0)  # right, a quarter of full magnitude
    valid = np.array([[True, True, True, False]])
    flow[0, 3] = (5.0, 5.0)
    rgb = flow_to_rgb(FlowField(flow_px=flow, from_k=0, to_k=1, valid=valid), max_px=2.0)
    assert tuple(rgb[0, 0]) == (255, 0, 0)
    assert rgb[0, 1, 0] == 0 and rgb[0, 1, 1] == rgb[0, 1, 2] == 255
    assert 55 < rgb[0, 2, 0] < 75 and rgb[0, 2, 1] == rgb[0, 2, 2] == 0
    assert tuple(rgb[0, 3]) == (0, 0, 0)


def test_depth_colours_and_holes():
    depth = np.array([[0.0, 0.5, 1.0, 3.0]], np.float32)
    rgb = depth_to_rgb(depth, 0.5, 1.0)
    assert tuple(rgb[0, 0]) == (0, 0, 0)
    assert rgb[0, 1, 2] > rgb[0, 1, 0]  # near = blue end of TURBO
    assert rgb[0, 2, 0] > rgb[0, 2, 2]  # far = red end
    np.testing.assert_array_equal(rgb[0, 2], rgb[0, 3])  # clipped


@pytest.mark.render
@pytest.mark.parametrize("suffix", [".mp4", ".gif"])
def test_write_preview_writes_a_readable_video(tmp_path, suffix):
    out = tmp_path / f"preview{suffix}"
    with open_renderer(small_scenario(frames=8)) as renderer:
        written = write_preview(renderer, out, frames=5, start=2, scale=0.5, progress=False)
    assert written == 5
    if suffix == ".gif":
        ok, animation = cv2.imreadanimation(str(out))
        assert ok and len(animation.frames) == 5
        shape = animation.frames[0].shape[:2]
    else:
        capture = cv2.VideoCapture(str(out))
        frames = []
        while True:
            ok, image = capture.read()
            if not ok:
                break
            frames.append(image)
        assert len(frames) == 5
        shape = frames[0].shape[:2]
        assert capture.get(cv2.CAP_PROP_FPS) == pytest.approx(30)
    assert shape == (60, 4 * 80)  # four 80x60 panels side by side


def test_video_writer_rejects_unknown_types(tmp_path):
    with pytest.raises(ConfigError, match=r"use one of \.mp4, \.avi, \.gif"):
        VideoWriter(tmp_path / "x.mkv", 30)


def test_cli_usage_errors_exit_2(tmp_path, capsys):
    scenario = REPO / "scenarios" / "ci" / "cracker_box.toml"
    existing = tmp_path / "p.mp4"
    existing.write_bytes(b"")
    assert main(["preview", str(scenario), "--out", str(existing)]) == 2
    assert "exists; pass --overwrite" in capsys.readouterr().err
    assert main(["preview", str(scenario), "--out", str(tmp_path / "no" / "p.mp4")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["preview", str(tmp_path / "missing.toml"), "--out", str(tmp_path / "a.mp4")]) == 2
    assert "does not exist" in capsys.readouterr().err
    argv = ["preview", str(scenario), "--out", str(tmp_path / "a.mp4")]
    assert main([*argv, "--assets", str(tmp_path / "nowhere")]) == 2  # was ignored
    assert "--assets" in capsys.readouterr().err


@pytest.mark.render
@pytest.mark.slow
def test_cli_writes_a_preview_of_a_ci_scenario(tmp_path, capsys):
    out = tmp_path / "preview.mp4"
    scenario = REPO / "scenarios" / "ci" / "cracker_box.toml"
    code = main(["preview", str(scenario), "--out", str(out), "--frames", "4", "--no-progress"])
    assert code == 0, capsys.readouterr().err
    assert "wrote 4 frames" in capsys.readouterr().out
    capture = cv2.VideoCapture(str(out))
    ok, image = capture.read()
    assert ok and image.shape == (240, 4 * 320, 3)
