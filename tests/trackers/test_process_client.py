"""A tracker in a child process: served Python trackers, crashes, hangs, protocol violations,
and no zombie left behind."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("msgpack", reason="the process extra (msgpack) is not installed")

from observation_schedules import build_observations, make_context, paper_schedule  # noqa: E402

from roft_sim.trackers import create_tracker, get_tracker_spec, run_tracker  # noqa: E402
from roft_sim.trackers.process import (  # noqa: E402
    ProcessTracker,
    ProcessTrackerConfig,
    ProtocolError,
    TrackerProcessError,
    codec,
    process_tracker_spec,
    serve,
    serve_main,
    tracker_name_from_command,
)
from roft_sim.trackers.process.transport import read_frame  # noqa: E402

CHILD = str(Path(__file__).with_name("process_child.py"))
FAST = ProcessTrackerConfig(step_timeout_s=5.0, start_timeout_s=20.0, exit_timeout_s=2.0)


def _assert_reaped(pid: int) -> None:
    """The child is no zombie of ours: it was waited for (waitpid finds no such child)."""
    with pytest.raises(ChildProcessError):
        os.waitpid(pid, os.WNOHANG)


def _child(mode: str, tiny_seq, config: ProcessTrackerConfig = FAST) -> ProcessTracker:
    return ProcessTracker(
        [sys.executable, CHILD, mode], make_context(tiny_seq, renderer=False), config=config
    )


@pytest.fixture(scope="module")
def observations(tiny_seq):
    return build_observations(tiny_seq, poses=paper_schedule(len(tiny_seq)))


@pytest.mark.slow  # the child imports every tracker plugin (ROFT, OpenCV, SciPy): 2-4 s
def test_a_served_python_tracker_gives_the_in_process_estimates(tiny_seq, observations):
    """detector-hold served by ``python -m roft_sim.trackers.process`` (poses cross as position and
    quaternion: equal to 1e-15), closed with bye: the child exits 0 and is reaped."""
    context = make_context(tiny_seq, renderer=False)
    expected = run_tracker(create_tracker(get_tracker_spec("detector-hold"), context), observations)
    spec = process_tracker_spec(f"{sys.executable} -m roft_sim.trackers.process detector-hold")
    with create_tracker(spec, make_context(tiny_seq, renderer=False), FAST) as tracker:
        got = run_tracker(tracker, observations)
        pid = tracker.pid
    assert tracker._process.returncode == 0
    _assert_reaped(pid)
    for a, b in zip(got, expected, strict=True):
        assert (a.k, a.valid, a.accepted_pose_ids) == (b.k, b.valid, b.accepted_pose_ids)
        np.testing.assert_allclose(a.T_cam_obj, b.T_cam_obj, rtol=0, atol=1e-15)


@pytest.mark.parametrize(
    ("mode", "match"),
    [
        ("wrong_k", r"estimate\.k: received frame 1, expected 0"),
        ("wrong_shape", r"estimate\.t_m: received shape \[4\], expected \[3\]"),
        ("nan", r"estimate\.v_obj_mps: received nan at index \[1\], expected finite numbers"),
        ("non_unit", r"estimate\.q_wxyz: received \[1\.0, 0\.1, 0\.0, 0\.0\] of norm"),
        ("missing", r"estimate: missing field 'w_radps'"),
        ("print", r"at observation k=0: .*(length|MessagePack)"),
    ],
)
def test_a_protocol_violation_names_the_field_and_kills_the_child(
    tiny_seq, observations, mode, match
):
    tracker = _child(mode, tiny_seq)
    tracker.reset(None)
    with pytest.raises(ProtocolError, match=match):
        tracker.step(observations[0])
    _assert_reaped(tracker.pid)
    with pytest.raises(TrackerProcessError, match="has ended"):
        tracker.step(observations[1])


def test_a_crash_fails_with_the_tail_of_stderr_and_is_reaped(tiny_seq, observations):
    tracker = _child("crash", tiny_seq)
    tracker.reset(None)
    with pytest.raises(
        TrackerProcessError,
        match=r"(?s)closed its pipes; it exited with status 3.*something went wrong in native code",
    ):
        tracker.step(observations[0])
    _assert_reaped(tracker.pid)


def test_a_hang_times_out_and_the_child_is_killed_and_reaped(tiny_seq, observations):
    config = ProcessTrackerConfig(step_timeout_s=0.3, start_timeout_s=20.0)
    tracker = _child("hang", tiny_seq, config)
    tracker.reset(None)
    with pytest.raises(
        TrackerProcessError, match=r"(?s)did not reply within 0\.3 s.*killed.*thinking very hard"
    ):
        tracker.step(observations[0])
    assert tracker._process.returncode == -9
    _assert_reaped(tracker.pid)


def test_an_error_reply_and_a_missing_program_are_reported(tiny_seq, observations):
    tracker = _child("error", tiny_seq)
    tracker.reset(None)
    with pytest.raises(TrackerProcessError, match="replied with an error: 'out of ideas'"):
        tracker.step(observations[0])
    _assert_reaped(tracker.pid)
    with pytest.raises(TrackerProcessError, match="cannot start"):
        ProcessTracker(["/nonexistent/tracker"], make_context(tiny_seq, renderer=False))


def _served_error(spec) -> str:
    """The error message ``serve(spec)`` replies to a parent that sent nothing yet."""
    to_child, from_parent = os.pipe()
    to_parent, from_child = os.pipe()
    try:
        assert serve(spec, stdin_fd=to_child, stdout_fd=from_child) == 1
        reply = codec.unpack(read_frame(to_parent))
    finally:
        for fd in (to_child, from_parent, to_parent, from_child):
            os.close(fd)
    assert reply["type"] == "error"
    return reply["message"]


def test_the_plugin_server_reports_unknown_names_and_specs_it_cannot_serve(capsys):
    """In process (the child's code path, without the start-up of a child)."""
    assert serve_main(["no-such-tracker"]) == 2
    assert "no tracker named 'no-such-tracker'" in capsys.readouterr().err
    message = _served_error(get_tracker_spec("roft"))
    assert "python -m roft_sim.harness.process_server roft" in message
    assert "detection_mode 'ideal'" in _served_error(get_tracker_spec("detector-ideal"))


def test_the_shared_file_is_unnamed_after_hello_and_used_only_when_accepted(tiny_seq, observations):
    example = Path(__file__).resolve().parents[2] / "examples" / "process_tracker_cpp"
    context = make_context(tiny_seq, renderer=False)
    with ProcessTracker([sys.executable, str(example / "cv_tracker.py")], context) as tracker:
        assert tracker._shared is not None  # the Python server accepts it
        assert not os.path.exists(tracker._shared.path)  # no file left behind, whatever happens
        tracker.reset(None)
        assert tracker.step(observations[0]).valid
    declining = _child("ok", tiny_seq)  # replies ready without "shm"
    assert declining._shared is None
    declining.reset(None)
    assert declining.step(observations[0]).k == 0
    declining.close()
    _assert_reaped(declining.pid)


def test_names_and_command_lines():
    assert (
        process_tracker_spec("python -m roft_sim.harness.process_server roft").name
        == "process-roft"
    )
    assert (
        tracker_name_from_command(["./build/cv_tracker", "--gain=2"]) == "process-cv_tracker-gain-2"
    )
    assert process_tracker_spec("./a.out", name="mine").name == "mine"
    with pytest.raises(ValueError, match="empty tracker command line"):
        process_tracker_spec("  ")
    with pytest.raises(ValueError, match="No closing quotation"):
        process_tracker_spec("tracker 'unbalanced")
    with pytest.raises(ValueError, match="step_timeout_s must be a positive number"):
        ProcessTrackerConfig(step_timeout_s=0)
