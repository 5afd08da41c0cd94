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
