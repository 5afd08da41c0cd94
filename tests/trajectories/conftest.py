"""Fixtures of the trajectory tests: the shared TUM and BVH files, each parsed or built once per
session (the BVH files are ~3 MB; the TUM builds take ~0.7 s each)."""

from __future__ import annotations

from pathlib import Path

import pytest

from roft_sim.trajectories import (
    FAST_YCB_CAMERA,
    BvhMotion,
    CapturedMotionConfig,
    CapturedTrajectory,
    build_captured_trajectory,
    read_bvh,
)

TUM_ROOMS = ("room1", "room2", "room4")
BVH_TRIALS = ("002_05", "002_06")


@pytest.fixture(scope="session")
def tum_paths(shared_trajectories_dir: Path) -> dict[str, Path]:
    """The shared TUM VI files by room name (``room1``, ``room2``, ``room4``)."""
    return {
        room: shared_trajectories_dir / "tum" / f"dataset-{room}_512_16.txt" for room in TUM_ROOMS
    }


@pytest.fixture(scope="session")
def bvh_paths(shared_trajectories_dir: Path) -> dict[str, Path]:
    """The shared BVH files by trial (``002_05``, ``002_06``)."""
    return {trial: shared_trajectories_dir / "bvh" / f"{trial}.bvh" for trial in BVH_TRIALS}


@pytest.fixture(scope="session")
def bvh_motions(bvh_paths: dict[str, Path]) -> dict[str, BvhMotion]:
    """Both shared BVH trials, parsed once."""
    return {trial: read_bvh(path) for trial, path in bvh_paths.items()}


@pytest.fixture(scope="session")
def tum_smoothed(tum_paths: dict[str, Path]) -> dict[str, CapturedTrajectory]:
    """The three TUM rooms, low-passed at 10 Hz with 2 s drift removal, placed (built once)."""
    return {
        room: build_captured_trajectory(
            CapturedMotionConfig(
                path=path,
                format="tum",
                lowpass_hz=10.0,
                remove_drift_window_s=2.0,
            ),
            FAST_YCB_CAMERA,
        )
        for room, path in tum_paths.items()
    }
