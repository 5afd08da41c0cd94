"""The parent side: a :class:`~roft_sim.trackers.Tracker` that runs in a child process.

``--tracker "process:<command line>"`` makes a :class:`TrackerSpec` (:func:`process_tracker_spec`)
whose factory starts the command (:class:`ProcessTracker`). The child speaks the protocol of
:mod:`roft_sim.trackers.process.codec` on its stdin/stdout; its stderr is read on a thread that
keeps the last lines, which every error quotes. Any failure (the child exits, does not reply in
time, sends an error or breaks the protocol) kills the child's process group, reaps the child and
raises :class:`~roft_sim.trackers.process.codec.TrackerProcessError`.
"""

from __future__ import annotations

import collections
import contextlib
import functools
import logging
import os
import re
import shlex
import signal
import subprocess
import threading
import time
import weakref
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import IO, Any, TypeVar

from roft_sim.errors import ConfigError
from roft_sim.records import Estimate, Observation
from roft_sim.trackers.base import TrackerContext, TrackerSpec
from roft_sim.trackers.process import codec
from roft_sim.trackers.process.codec import ProtocolError, TrackerProcessError
from roft_sim.trackers.process.shared import SharedWriter
from roft_sim.trackers.process.transport import (
    Deadline,
    EndOfStream,
    enlarge_pipe,
    receive_frame,
    send_frame,
)

__all__ = [
    "PROCESS_PREFIX",
    "ProcessTrackerConfig",
    "ProcessTracker",
    "process_tracker_spec",
    "tracker_name_from_command",
]

PROCESS_PREFIX = "process:"
"""A tracker name starting with this is a command line to run as a tracker process."""

_log = logging.getLogger(__name__)
_SEED_BOUND = 2**63
_SHARED_BYTES_PER_PIXEL = 18
"""Shared file size per image pixel: rgb 3, depth 4, full-resolution flow 8 and validity 1,
two masks 2 [bytes]; what does not fit goes inline."""
_T = TypeVar("_T")


@dataclass(frozen=True, slots=True, kw_only=True)
class ProcessTrackerConfig:
    """Settings of a tracker process (``--tracker-config`` of a ``process:`` tracker)."""

    step_timeout_s: float = 30.0
    """Longest wait for the reply to one observation or reset [s] (writing the observation
    included); a child that takes longer is killed and its cell fails."""
    start_timeout_s: float = 120.0
    """Longest wait for the reply to ``hello`` [s] (the child's start-up: imports, loading)."""
    exit_timeout_s: float = 5.0
    """How long a child may take to exit after ``bye`` before it is killed [s]."""
    stderr_tail_lines: int = 40
    """Lines of the child's stderr kept and quoted in errors."""
    shared_memory: bool = True
    """Offer the child a shared file for large arrays (images, flow, masks); a child that
    accepts gets them without a copy through the pipe (docs/process.md)."""

    def __post_init__(self) -> None:
        for name in ("step_timeout_s", "start_timeout_s", "exit_timeout_s"):
            value = getattr(self, name)
            if not isinstance(value, int | float) or not value > 0:
                raise ConfigError(f"{name} must be a positive number of seconds, got {value!r}")
        if self.stderr_tail_lines < 1:
            raise ConfigError(f"stderr_tail_lines must be >= 1, got {self.stderr_tail_lines}")


class _StderrTail:
    """Reads a pipe line by line on a daemon thread, keeping the last lines."""

    def __init__(self, pipe: IO[bytes], lines: int, name: str) -> None:
        self._lines: collections.deque[str] = collections.deque(maxlen=lines)
        self._thread = threading.Thread(
            target=self._read, args=(pipe, name), name=f"stderr of {name}", daemon=True
        )
        self._thread.start()

    def _read(self, pipe: IO[bytes], name: str) -> None:
        with pipe:
            for raw in pipe:
                line = raw.decode("utf-8", "replace").rstrip()
                self._lines.append(line)
                _log.debug("%s: %s", name, line)

    def text(self, wait_s: float = 1.0) -> str:
        """The kept lines (after waiting up to ``wait_s`` for the pipe to close)."""
        self._thread.join(wait_s)
        return "\n".join(self._lines)


def _release(process: subprocess.Popen[bytes], shared: SharedWriter | None) -> None:
    """Kills and reaps the child (:func:`_kill`), and removes the shared file."""
    try:
        _kill(process)
    finally:
        if shared is not None:
            shared.close()


def _kill(process: subprocess.Popen[bytes]) -> None:
    """Kills the child's process group (it leads its own session) and reaps the child."""
    if process.poll() is None:  # not reaped yet, so its pid (the group id) is not reused
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(process.pid, signal.SIGKILL)
    process.wait()
    for pipe in (process.stdin, process.stdout):
        if pipe is not None:
            with contextlib.suppress(OSError):
                pipe.close()


class ProcessTracker:
    """A tracker that runs as a child process speaking the tracker process protocol.

    Starts ``command`` at construction and sends ``hello`` (the context, a seed drawn from
    ``context.rng``); :meth:`close` sends ``bye`` and reaps it (the harness calls it after the
    run; it also runs when the object is garbage-collected).

    Raises:
        TrackerProcessError: from any method, when the child crashed, hung, replied with an
            error or broke the protocol; the child is then killed and reaped.
    """

    def __init__(
        self,
        command: Sequence[str],
        context: TrackerContext,
        *,
        config: ProcessTrackerConfig | None = None,
        name: str = "process",
    ) -> None:
        self.config = config if config is not None else ProcessTrackerConfig()
        self.name = name
        self.command = tuple(command)
        self._shared: SharedWriter | None = None
        if self.config.shared_memory:
            pixels = context.intrinsics.width_px * context.intrinsics.height_px
            self._shared = SharedWriter(pixels * _SHARED_BYTES_PER_PIXEL + 16 * 64)
        try:
            self._process = subprocess.Popen(
                self.command,
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                bufsize=0,
                start_new_session=True,
            )
        except OSError as e:
            if self._shared is not None:
                self._shared.close()
            raise TrackerProcessError(
                f"tracker process {name!r}: cannot start {shlex.join(self.command)!r}: {e}"
            ) from e
        self._finalizer = weakref.finalize(self, _release, self._process, self._shared)
        assert self._process.stdin is not None and self._process.stdout is not None  # PIPE
        self._stdin = self._process.stdin.fileno()
        self._stdout = self._process.stdout.fileno()
        for fd in (self._stdin, self._stdout):
            enlarge_pipe(fd)
        os.set_blocking(self._stdin, False)
        assert self._process.stderr is not None
        self._stderr = _StderrTail(self._process.stderr, self.config.stderr_tail_lines, name)
        hello = codec.hello_message(
            intrinsics=context.intrinsics,
            fps=context.fps,
            object_model=context.object_model,
            seed=int(context.rng.integers(_SEED_BOUND)),
            shared=self._shared,
        )
        try:
            reply = self._call(hello, self.config.start_timeout_s, "hello")
        finally:
            if self._shared is not None:
                self._shared.unlink()  # the child opened it (or never will)
        if not self._guard("hello", lambda: codec.check_ready(reply, "hello")):
            self._shared = None  # the child takes every array inline

    @property
    def pid(self) -> int:
        """Process id of the child."""
        return self._process.pid

    def reset(self, initial: Estimate | None) -> None:
        """Sends ``reset`` and waits for ``ready``."""
        reply = self._call(codec.reset_message(initial), self.config.step_timeout_s, "reset")
        self._guard("reset", lambda: codec.check_ready(reply, "reset"))

    def step(self, observation: Observation) -> Estimate:
        """Sends observation ``k`` and returns the child's estimate for it."""
        doing = f"observation k={observation.k}"
        message = self._guard(doing, lambda: codec.observation_message(observation, self._shared))
        reply = self._call(message, self.config.step_timeout_s, doing)
        return self._guard(doing, lambda: codec.estimate_from_message(reply, k=observation.k))

    def close(self) -> None:
        """Sends ``bye``, waits up to ``exit_timeout_s`` for the child to exit, then kills the
        process group and reaps the child. Safe to call twice."""
        if not self._finalizer.alive:
            return
        if self._process.poll() is None:
            with contextlib.suppress(TrackerProcessError, EndOfStream, Deadline, OSError):
                send_frame(self._stdin, codec.pack(codec.bye_message()), self._deadline(1.0))
            with contextlib.suppress(subprocess.TimeoutExpired):
                self._process.wait(self.config.exit_timeout_s)
        self._finalizer()

    def __enter__(self) -> ProcessTracker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------------------ internals
    @staticmethod
    def _deadline(timeout_s: float) -> float:
        return time.monotonic() + timeout_s

    def _call(self, message: Mapping[str, Any], timeout_s: float, doing: str) -> dict[str, Any]:
        """Sends ``message`` and returns the reply (an ``error`` reply raises)."""
        if not self._finalizer.alive:
            raise TrackerProcessError(
                f"tracker process {self.name!r} has ended; cannot send {doing}"
            )
        deadline = self._deadline(timeout_s)
        try:
            send_frame(self._stdin, codec.pack(message), deadline)
            reply = codec.unpack(receive_frame(self._stdout, deadline))
        except Deadline:
            raise self._failure(
                doing,
                f"did not reply within {timeout_s:g} s (raise the timeout with step_timeout_s or "
                "start_timeout_s in --tracker-config)",
            ) from None
        except EndOfStream:
            raise self._failure(doing, "closed its pipes") from None
        except ProtocolError as e:
            raise self._failure(doing, str(e), protocol=True) from None
        if reply["type"] == "error":
            raise self._failure(doing, f"replied with an error: {reply.get('message')!r}")
        return reply

    def _guard(self, doing: str, check: Callable[[], _T]) -> _T:
        try:
            return check()
        except ProtocolError as e:
            raise self._failure(doing, str(e), protocol=True) from None

    def _failure(self, doing: str, what: str, *, protocol: bool = False) -> TrackerProcessError:
        """Kills and reaps the child; the error to raise, with the tail of its stderr."""
        self._finalizer()
        status = self._process.returncode
        ended = f"exited with status {status}" if status is not None and status >= 0 else "killed"
        tail = self._stderr.text() or "(nothing)"
        kind = ProtocolError if protocol else TrackerProcessError
        return kind(
            f"tracker process {self.name!r} ({shlex.join(self.command)}), at {doing}: {what}; "
            f"it {ended}. Last lines of its stderr:\n{tail}"
        )


_UNSAFE = re.compile(r"[^A-Za-z0-9._+]+")
_INTERPRETERS = re.compile(r"^python[0-9.]*$")
_SERVERS = ("roft_sim.trackers.process", "roft_sim.harness.process_server")


def tracker_name_from_command(argv: Sequence[str], *, max_chars: int = 60) -> str:
    """A readable, filesystem-safe name for a command: ``process-`` and its words (a Python
    interpreter left out, ``-m pkg.module`` as ``module``, roft_sim's own servers left out, paths
    by their last part), cut to ``max_chars``. E.g. ``process-roft`` for ``python -m
    roft_sim.harness.process_server roft``."""
    words = list(argv)
    if words and _INTERPRETERS.match(os.path.basename(words[0])):
        words = words[1:]
        if words[:1] == ["-m"] and len(words) > 1:
            module = words[1]
            words = words[2:] if module in _SERVERS else [module.rsplit(".", 1)[-1], *words[2:]]
    parts = [os.path.basename(w.rstrip("/")) or w for w in words]
    name = _UNSAFE.sub("-", " ".join(["process", *parts])).strip("-.")
    return name[:max_chars].rstrip("-.")


def _create(
    argv: tuple[str, ...], name: str, config: ProcessTrackerConfig, context: TrackerContext
) -> ProcessTracker:
    return ProcessTracker(argv, context, config=config, name=name)


def process_tracker_spec(command_line: str, *, name: str | None = None) -> TrackerSpec:
    """The :class:`TrackerSpec` of ``process:<command_line>`` (split as a POSIX shell would).

    Raises:
        ConfigError: an empty or unbalanced command line.
    """
    try:
        argv = tuple(shlex.split(command_line))
    except ValueError as e:
        raise ConfigError(f"tracker command line {command_line!r}: {e}") from None
    if not argv:
        raise ConfigError(
            f"empty tracker command line after {PROCESS_PREFIX!r}; expected e.g. "
            f"'{PROCESS_PREFIX}python -m roft_sim.trackers.process detector-hold'"
        )
    label = name or tracker_name_from_command(argv)
    return TrackerSpec(
        name=label,
        description=f"tracker process: {shlex.join(argv)}",
        config_type=ProcessTrackerConfig,
        factory=functools.partial(_create, argv, label),
    )
