"""run_work_unit writes frames on writer threads while the next frame is generated, in frame
order, with a bounded number of frames waiting."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field

import pytest

from roft_sim.generation import WorkUnit, run_work_unit


@dataclass
class _Frame:
    k: int


@dataclass
class _Generator:
    """Yields frames and records how far ahead of the writes it got."""

    writer: _Writer
    max_ahead: int = 0

    def frames(self, start: int, stop: int, *, pipelined: bool = True):
        for k in range(start, stop):
            self.max_ahead = max(self.max_ahead, k - start - len(self.writer.written))
            yield _Frame(k)


@dataclass
class _Writer:
    delay_s: float = 0.01
    written: list[int] = field(default_factory=list)
    threads: set[int] = field(default_factory=set)
    fail_at: int | None = None

    def write_frame(self, frame: _Frame) -> None:
        time.sleep(self.delay_s)  # slower than generating: the queue fills up
        if frame.k == self.fail_at:
            raise OSError(f"disk full at frame {frame.k}")
        self.threads.add(threading.get_ident())
        self.written.append(frame.k)


@dataclass
class _Job:
    writer: _Writer


@pytest.mark.parametrize("writer_threads", [1, 2])
def test_frames_are_written_off_the_generating_thread_in_order_with_a_bounded_queue(
    writer_threads,
):
    writer = _Writer()
    generator = _Generator(writer)
    reported: list[int] = []
    n = run_work_unit(
        WorkUnit(0, 3, 15),
        _Job(writer),
        generator,
        report=reported.append,
        writer_threads=writer_threads,
    )
    assert n == 12 and sorted(writer.written) == list(range(3, 15)) and reported == [1] * 12
    assert threading.get_ident() not in writer.threads
    assert 1 <= generator.max_ahead <= writer_threads + 1


def test_without_writer_threads_frames_are_written_in_the_generating_thread():
    writer = _Writer(delay_s=0.0)
    run_work_unit(WorkUnit(0, 0, 4), _Job(writer), _Generator(writer), writer_threads=0)
    assert writer.written == [0, 1, 2, 3] and writer.threads == {threading.get_ident()}


def test_a_failed_write_is_raised_and_the_frames_before_it_are_kept():
    writer = _Writer(fail_at=5)
    with pytest.raises(OSError, match="disk full at frame 5"):
        run_work_unit(WorkUnit(0, 0, 10), _Job(writer), _Generator(writer), writer_threads=2)
    assert set(range(5)) <= set(writer.written) and 5 not in writer.written
