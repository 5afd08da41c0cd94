"""Unreadable trajectory inputs give a clear error, never a traceback (review regressions)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from roft_sim.cli import main
from roft_sim.errors import ConfigError, DatasetFormatError
from roft_sim.geometry import transform_from_rt
from roft_sim.trajectories import read_pose_samples
from roft_sim.trajectories.samples import PoseSamples, lowpass_poses

FORMATS = ("tum", "bvh", "fast-ycb", "bop", "csv")


def _read(path: Path, fmt: str) -> PoseSamples:
    return read_pose_samples(path, fmt, joint="CC_Base_L_Hand" if fmt == "bvh" else None)


@pytest.mark.parametrize("fmt", FORMATS)
def test_a_binary_file_is_a_dataset_format_error(fmt: str, tmp_path: Path) -> None:
    path = tmp_path / "binary.txt"
    path.write_bytes(b"\xff\xfe\x00 not text \x80\x81")
    with pytest.raises(DatasetFormatError, match="binary.txt"):
        _read(path, fmt)


@pytest.mark.parametrize("fmt", ("tum", "bvh", "csv"))
def test_a_folder_instead_of_a_file_is_a_dataset_format_error(fmt: str, tmp_path: Path) -> None:
    with pytest.raises(DatasetFormatError, match="is a folder"):
        _read(tmp_path, fmt)


def test_lowpass_on_too_few_samples_is_a_config_error() -> None:
    t = np.arange(12) / 120.0
    T = transform_from_rt(np.eye(3), np.c_[t, t, t + 0.5])
    samples = PoseSamples(t_s=t, T_ref_obj=T, source="short.txt")
    with pytest.raises(ConfigError, match="lowpass_hz"):
        lowpass_poses(samples, 10.0)


@pytest.mark.parametrize("verb", ["stats", "export"])
@pytest.mark.parametrize("fps", ["0", "-30", "nan"])
def test_cli_rejects_a_non_positive_fps_with_exit_2(
    verb: str, fps: str, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    argv = ["trajectory", verb, "--synthetic", "--fps", fps]
    if verb == "export":
        argv += ["--out", str(tmp_path / "t.csv")]
    assert main(argv) == 2
    assert "--fps" in capsys.readouterr().err


@pytest.mark.parametrize("verb", ["stats", "export"])
def test_cli_rejects_a_negative_seed_with_exit_2(
    verb: str, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """Review regression: --seed -1 used to end in numpy's 'expected non-negative integer'."""
    argv = ["trajectory", verb, "--synthetic", "--seed", "-1"]
    if verb == "export":
        argv += ["--out", str(tmp_path / "t.csv")]
    assert main(argv) == 2
    assert "--seed must be an integer >= 0, got -1" in capsys.readouterr().err
    assert not (tmp_path / "t.csv").exists()


@pytest.mark.parametrize("seed", [-1, 1.5, True])
def test_synthetic_config_rejects_a_seed_numpy_cannot_take(seed: object) -> None:
    """Scenario files build this config too: ``seed = -1`` there used to be a traceback."""
    from roft_sim.trajectories import SyntheticMotionConfig

    with pytest.raises(ConfigError, match="seed must be an integer >= 0"):
        SyntheticMotionConfig(seed=seed)  # type: ignore[arg-type]


def test_cli_export_to_a_folder_is_a_usage_error(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """Review regression: --out FOLDER --overwrite used to end in IsADirectoryError."""
    argv = ["trajectory", "export", "--synthetic", "--out", str(tmp_path), "--overwrite"]
    assert main(argv) == 2
    assert f"--out must be a file path, {str(tmp_path)!r} is a folder" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--lowpass-hz", "10"], "--lowpass-hz applies only to a trajectory FILE"),
        (["--drift-window-s", "-2"], "--drift-window-s applies only to a trajectory FILE"),
        (
            ["--speed-scale", "2", "--window-s", "0", "1"],
            "--window-s, --speed-scale apply only to a trajectory FILE",
        ),
        (["--include-gaps"], "--include-gaps applies only to a trajectory FILE"),
        (["--duration-s", "0"], "--duration-s must be a positive number of seconds"),
        (["--duration-s", "inf"], "--duration-s must be a positive number of seconds"),
        (["--duration-s", "3600.5"], "at most 3600 (an hour), got 3600.5"),
        (["--fps", "1e12"], "more than 1000000 samples"),
    ],
)
def test_cli_synthetic_stats_refuses_options_it_would_ignore_or_cannot_run(
    options: list[str], message: str, capsys: pytest.CaptureFixture
) -> None:
    """Review regression: file-only options were accepted with --synthetic and ignored, and
    --duration-s / --fps had no upper bound (minutes of work, or running out of memory)."""
    assert main(["trajectory", "stats", "--synthetic", *options]) == 2
    assert message in capsys.readouterr().err


def test_cli_synthetic_options_with_a_file_are_a_usage_error(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    path = tmp_path / "t.txt"
    path.write_text("0 0 0 0.5 0 0 0 1\n")
    assert main(["trajectory", "stats", str(path), "--format", "tum", "--seed", "3"]) == 2
    assert "--seed applies only to --synthetic, not to a FILE" in capsys.readouterr().err
