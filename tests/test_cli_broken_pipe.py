"""The CLI when the reader of its stdout goes away (``roft-sim ... | head``): no traceback."""

from __future__ import annotations

import subprocess
import sys

import pytest


@pytest.mark.skipif(sys.platform != "linux", reason="detects the closed pipe with Linux poll()")
@pytest.mark.parametrize("argv", [["trackers", "--json"], ["faults", "show", "paper"]])
def test_a_closed_stdout_pipe_gives_no_traceback(argv):
    proc = subprocess.Popen(
        [sys.executable, "-m", "roft_sim", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    proc.stdout.close()  # the reader is gone before anything is printed, as after `| head -1`
    _, err = proc.communicate(timeout=120)
    assert b"Traceback" not in err and b"BrokenPipeError" not in err, err.decode()
    assert proc.returncode == 1
