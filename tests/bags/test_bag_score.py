"""`roft-sim bag export-run` and `roft-sim bag score`: a run's estimates as a bag, scored back to
the run's metrics.json, and the scoring's matching and error paths."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from bag_readers import (
    EchoConfig,
    EchoTracker,
    read_with_mcap_ros2,
    read_with_rosbags,
    write_box_dataset,
)

from roft_sim.bags.messages import (
    POSE_STAMPED,
    TWIST_STAMPED,
    pose_stamped_msg,
    stamp_ns_from_frame,
    twist_stamped_msg,
)
from roft_sim.bags.reader import bag_metadata
from roft_sim.bags.score import score_bag
from roft_sim.bags.writer import open_bag
from roft_sim.cli import main
from roft_sim.datasets import open_sequence
from roft_sim.errors import ConfigError
from roft_sim.faults import load_faults
from roft_sim.harness import RunOptions, open_sequences, run_sequences
from roft_sim.records import Estimate, Observation
from roft_sim.trackers import TrackerSpec

FPS = 30
N_FRAMES = 36


@pytest.fixture(scope="module")
def sequence_dir(tmp_path_factory):
    root = tmp_path_factory.mktemp("data")
    return write_box_dataset(root, names=("box",), n_frames=N_FRAMES, width=32, height=24) / "box"


def assert_metrics_match(scored: dict, reference: dict, *, rel: float = 1e-9) -> None:
    """Every metric ``bag score`` wrote equals the run's, in ALL, MEAN and the sequence."""
    assert set(scored) == set(reference)
    for name, entry in scored.items():
        keys = [k for k in entry if k != "bag"]
        assert len(keys) >= 11 and set(keys) <= set(reference[name]), name
        for key in keys:
            got, want = entry[key], reference[name][key]
            if isinstance(want, list):
                assert got == pytest.approx(want, rel=rel, abs=1e-12), (name, key)
            elif want is None or isinstance(want, int):
                assert got == want, (name, key)
            else:
                assert math.isclose(got, want, rel_tol=rel, abs_tol=1e-12), (name, key, got, want)


def export_and_score(run_dir, tmp_path, sequence_dir, *extra: str) -> dict:
    bag = tmp_path / "estimates.mcap"
    assert main(["bag", "export-run", str(run_dir), "--out", str(bag), "--json"]) == 0
    out = tmp_path / "scored"
    args = ["bag", "score", str(bag), "--dataset", str(sequence_dir), "--out", str(out)]
    assert main([*args, "--pose-topic", "/tracker/pose", "--twist-topic", "/tracker/twist"]) == 0
    return json.loads((out / "metrics.json").read_text())


def test_round_trip_of_a_run_without_spatial_twists(sequence_dir, tmp_path, capsys):
    run_dir = tmp_path / "run"
    args = ["run", str(sequence_dir), "--tracker", "pose-only-ukf", "--faults", "reorder"]
    args += ["--invalid", "hold", "--flow", "none", "--out", str(run_dir), "--no-progress"]
    assert main(args) == 0
    reference = json.loads((run_dir / "metrics.json").read_text())
    assert reference["box"]["frames"] < N_FRAMES  # hold: frames before the first pose left out
    scored = export_and_score(run_dir, tmp_path, sequence_dir)
    assert_metrics_match(scored, reference)
    run = json.loads((tmp_path / "scored" / "run.json").read_text())
    assert (
        run["kind"] == "bag-score" and run["invalid"] == "hold" and run["twist_linear"] == "origin"
    )
    assert "invalid estimates: hold" in capsys.readouterr().out


class TwistEcho(EchoTracker):
    """The echo tracker with a spatial twist on most frames (none on every fourth)."""

    def step(self, observation: Observation) -> Estimate:
        e = super().step(observation)
        if observation.k % 4 == 0:
            return e
        twist = np.array([0.02, -0.01, 0.03, 0.4, -0.2, 0.1]) * (1 + 0.05 * observation.k)
        return dataclasses.replace(e, spatial_twist=twist)


TWIST_ECHO = TrackerSpec(
    name="twist-echo", description="test", config_type=EchoConfig, factory=TwistEcho
)


@pytest.mark.parametrize(("faults", "invalid"), [("chaos", "hold"), ("reorder", "failure")])
def test_round_trip_of_a_run_with_spatial_twists(sequence_dir, tmp_path, faults, invalid):
    run_dir = tmp_path / "run"
    options = RunOptions(
        tracker="twist-echo", faults=load_faults(faults), flow="none", invalid=invalid
    )
    run_sequences(open_sequences([sequence_dir]), options, run_dir, spec=TWIST_ECHO)
    reference = json.loads((run_dir / "metrics.json").read_text())
    assert reference["box"]["frames_velocity"] > 0
    assert invalid == "hold" or reference["box"]["frames_invalid"] > 0
    scored = export_and_score(run_dir, tmp_path, sequence_dir)
    assert_metrics_match(scored, reference)
    bag = tmp_path / "estimates.mcap"
    for messages in (read_with_mcap_ros2(bag), read_with_rosbags(bag)):
        assert {t for t, *_ in messages} == {"/tracker/pose", "/tracker/twist"}
        assert all(log == stamp for _, _, log, stamp, _ in messages)


class HeldWithoutTwist(TwistEcho):
    """TwistEcho whose frame after each frame without a spatial twist is invalid: under
    ``hold`` it is scored with that frame's ``v_obj`` and ``w``, which its bag must carry
    exactly (as a body twist) for the score to give them back."""

    def step(self, observation: Observation) -> Estimate:
        e = super().step(observation)
        if observation.k % 4 == 1 and observation.k > 1:
            return Estimate.invalid(observation.k)
        return dataclasses.replace(e, v_obj_mps=e.v_obj_mps + 0.1, w_radps=e.w_radps - 0.2)


def test_round_trip_when_a_held_frame_has_no_spatial_twist(sequence_dir, tmp_path):
    run_dir = tmp_path / "run"
    options = RunOptions(tracker="held", faults=load_faults("none"), flow="none", invalid="hold")
    spec = TrackerSpec(
        name="held", description="test", config_type=EchoConfig, factory=HeldWithoutTwist
    )
    run_sequences(open_sequences([sequence_dir]), options, run_dir, spec=spec)
    reference = json.loads((run_dir / "metrics.json").read_text())
    assert reference["box"]["frames_invalid"] > 0
    assert_metrics_match(export_and_score(run_dir, tmp_path, sequence_dir), reference)


@pytest.mark.parametrize("faults", ["paper", pytest.param("chaos", marks=pytest.mark.slow)])
def test_round_trip_of_roft(sequence_dir, tmp_path, faults):
    run_dir = tmp_path / "run"
    args = ["run", str(sequence_dir), "--tracker", "roft", "--faults", faults, "--flow", "gt"]
    assert main([*args, "--out", str(run_dir), "--no-progress"]) == 0
    reference = json.loads((run_dir / "metrics.json").read_text())
    assert_metrics_match(export_and_score(run_dir, tmp_path, sequence_dir), reference)
    metadata = bag_metadata([tmp_path / "estimates.mcap"])
    assert metadata["twist_linear"] == "spatial" and metadata["tracker"] == "roft"


def write_estimates_bag(path, poses, twists=()) -> None:
    """A bag of ``(stamp_ns, log_ns, T)`` poses and ``(stamp_ns, log_ns, v, w)`` twists."""
    with open_bag(path) as bag:
        for stamp, log, T in poses:
            bag.write("/est/pose", POSE_STAMPED, pose_stamped_msg(stamp, T), log)
        for stamp, log, v, w in twists:
            bag.write("/est/twist", TWIST_STAMPED, twist_stamped_msg(stamp, v, w), log)


def test_score_matches_stamps_to_frames_and_the_last_message_wins(sequence_dir, tmp_path):
    sequence = open_sequence(sequence_dir)
    truth = sequence.ground_truth().T_cam_obj
    wrong = truth[3].copy()
    wrong[0, 3] += 0.5
    # stamps 0.3 ms off (within the tolerance), no pose for frame 5
    poses = [
        (stamp_ns_from_frame(k, FPS) + 300_000, 0, truth[k]) for k in range(N_FRAMES) if k != 5
    ]
    poses.append((stamp_ns_from_frame(3, FPS), 10**9, wrong))  # frame 3 again, logged later
    v = np.array([0.1, 0.0, 0.0])
    twists = [(stamp_ns_from_frame(k, FPS), 0, v, np.zeros(3)) for k in range(N_FRAMES)]
    bag = tmp_path / "est.mcap"
    write_estimates_bag(bag, poses, twists)
    score = score_bag(bag, sequence, pose_topic="/est/pose", twist_topic="/est/twist")
    estimates = score.read.estimates
    assert not estimates[5].valid and all(e.valid for i, e in enumerate(estimates) if i != 5)
    np.testing.assert_array_equal(estimates[3].T_cam_obj[:3, 3], wrong[:3, 3])
    np.testing.assert_array_equal(estimates[7].v_obj_mps, v)  # origin: twist.linear is v_obj
    assert score.read.summary() == {
        "pose_messages": N_FRAMES,
        "twist_messages": N_FRAMES,
        "replaced": 1,
        "frames_with_pose": N_FRAMES - 1,
    }
    assert score.metrics["box"]["frames_invalid"] == 1  # failure: no metadata, no --invalid
    late = [(stamp_ns_from_frame(2, FPS) + 2_000_000, 0, truth[2])]  # 2 ms off its frame
    write_estimates_bag(bag, late)
    with pytest.raises(ConfigError, match=r"1 of 1 messages on /est/pose match no frame"):
        score_bag(bag, sequence, pose_topic="/est/pose")
    assert (
        score_bag(bag, sequence, pose_topic="/est/pose", tolerance_ns=3_000_000).read.summary()[
            "frames_with_pose"
        ]
        == 1
    )


def test_score_error_paths(sequence_dir, tmp_path, capsys):
    bag = tmp_path / "est.mcap"
    truth = open_sequence(sequence_dir).ground_truth().T_cam_obj
    write_estimates_bag(bag, [(0, 0, truth[0])], [(0, 0, np.zeros(3), np.zeros(3))])
    out = tmp_path / "out"
    base = ["bag", "score", str(bag), "--dataset", str(sequence_dir), "--out", str(out)]
    assert main([*base, "--pose-topic", "/nope"]) == 2
    assert "--pose-topic '/nope' is not in the bag" in capsys.readouterr().err
    assert main([*base, "--pose-topic", "/est/twist"]) == 2
    err = capsys.readouterr().err
    assert "carries geometry_msgs/msg/TwistStamped; expected geometry_msgs/msg/PoseStamped" in err
    missing = ["bag", "score", str(bag), "--dataset", str(tmp_path / "absent"), "--out", str(out)]
    assert main([*missing, "--pose-topic", "/est/pose"]) == 2
    assert "absent" in capsys.readouterr().err
    assert main(["bag", "score", str(tmp_path / "x.mcap"), *base[3:], "--pose-topic", "/a"]) == 2
    assert "does not exist" in capsys.readouterr().err
    out.mkdir()
    (out / "keep").write_text("")
    assert main([*base, "--pose-topic", "/est/pose"]) == 2
    assert "not empty; pass --overwrite" in capsys.readouterr().err
    assert main([*base, "--pose-topic", "/est/pose", "--overwrite"]) == 0
    assert not (out / "keep").exists() and (out / "box" / "estimates.npz").is_file()


def test_export_run_error_paths_and_a_bag_for_another_sequence(sequence_dir, tmp_path, capsys):
    assert main(["bag", "export-run", str(tmp_path), "--out", str(tmp_path / "e.mcap")]) == 2
    assert "is not a roft-sim run folder" in capsys.readouterr().err
    run_dir = tmp_path / "run"
    args = ["run", str(sequence_dir), "--tracker", "detector-hold", "--faults", "none"]
    assert main([*args, "--flow", "none", "--out", str(run_dir), "--no-progress"]) == 0
    bag = tmp_path / "e.mcap"
    assert main(["bag", "export-run", str(run_dir), "--out", str(bag)]) == 0
    assert main(["bag", "export-run", str(run_dir), "--out", str(bag)]) == 2
    assert "exists; pass --overwrite" in capsys.readouterr().err
    other = write_box_dataset(tmp_path / "other", names=("short",), n_frames=8, width=16, height=12)
    score = [
        "bag",
        "score",
        str(bag),
        "--dataset",
        str(other / "short"),
        "--out",
        str(tmp_path / "o"),
    ]
    assert main([*score, "--pose-topic", "/tracker/pose"]) == 2
    assert "the bag was written for 36 frames, the dataset 'short' has 8" in capsys.readouterr().err
