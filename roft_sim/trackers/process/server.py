"""The child side: :func:`serve` runs a Python tracker as a tracker process.

``serve`` reads frames on stdin and writes replies on stdout. Before it starts, it moves the
process's stdout to a private descriptor and points descriptor 1 at stderr, so a ``print`` in the
tracker (or a library it calls) cannot corrupt the protocol.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys
import traceback
from collections.abc import Callable
from typing import Any

import numpy as np

from roft_sim.errors import PluginError, RoftSimError
from roft_sim.records import DepthRenderer, ObjectModel
from roft_sim.trackers.base import (
    Tracker,
    TrackerContext,
    TrackerSpec,
    checked_step,
    create_tracker,
)
from roft_sim.trackers.process import codec
from roft_sim.trackers.process.codec import ProtocolError
from roft_sim.trackers.process.shared import SharedReader
from roft_sim.trackers.process.transport import read_frame, write_frame

__all__ = ["serve", "serve_main", "TrackerFactory"]

TrackerFactory = Callable[[TrackerContext], Tracker]
"""Builds the served tracker from the context that ``hello`` carried."""


def _keep_freed_memory() -> None:
    """Large arrays from the heap, and freed memory kept for reuse (glibc's ``mallopt``; a no-op
    elsewhere). Each observation's arrays are fresh copies; without this, glibc maps new pages for
    them and returns them on free, and the page faults cost more than the copies."""
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return
    m_trim_threshold, m_mmap_threshold = -1, -3
    mallopt(m_mmap_threshold, 32 << 20)  # glibc's largest on 64-bit
    mallopt(m_trim_threshold, 1 << 30)


def _protocol_fds(stdin_fd: int | None, stdout_fd: int | None) -> tuple[int, int]:
    """The descriptors to speak on; with the defaults, stdout is moved off descriptor 1."""
    if stdout_fd is None:
        sys.stdout.flush()
        stdout_fd = os.dup(1)
        os.dup2(2, 1)
    return (0 if stdin_fd is None else stdin_fd), stdout_fd


def _factory_of(
    tracker: TrackerFactory | TrackerSpec,
    config: Any,
    depth_renderer_factory: Callable[[ObjectModel], DepthRenderer] | None,
) -> tuple[str, TrackerFactory]:
    if not isinstance(tracker, TrackerSpec):
        return getattr(tracker, "__name__", "python"), tracker
    spec = tracker
    if spec.detection_mode != "stream":
        raise PluginError(
            f"tracker {spec.name!r} has detection_mode {spec.detection_mode!r}; a served tracker "
            "gets the detections of the fault stream ('stream'), so run it in process"
        )
    if spec.needs_depth_renderer and depth_renderer_factory is None:
        raise PluginError(
            f"tracker {spec.name!r} needs a depth renderer; serve it with "
            f"`python -m roft_sim.harness.process_server {spec.name}` (which builds MuJoCo's from "
            "the mesh sent in hello), or pass depth_renderer_factory to serve()"
        )

    def build(context: TrackerContext) -> Tracker:
        if spec.needs_depth_renderer and depth_renderer_factory is not None:
            context = TrackerContext(
                intrinsics=context.intrinsics,
                fps=context.fps,
                object_model=context.object_model,
                rng=context.rng,
                depth_renderer=depth_renderer_factory(context.object_model),
            )
        return create_tracker(spec, context, config)

    return spec.name, build


def _start(
    read: Callable[[], dict[str, Any] | None], build: TrackerFactory
) -> tuple[Tracker, codec.HelloContent, SharedReader | None]:
    """Reads ``hello``, builds the tracker and opens the shared file it offers."""
    hello = read()
    if hello is None:
        raise ProtocolError("the parent closed stdin before hello")
    content = codec.context_from_hello(hello)
    context = TrackerContext(
        intrinsics=content.intrinsics,
        fps=content.fps,
        object_model=content.object_model,
        rng=np.random.default_rng(content.seed),
    )
    shared = None
    if content.shm_path is not None:
        shared = SharedReader(content.shm_path, content.shm_bytes)
    return build(context), content, shared


def _step(
    tracker: Tracker,
    message: dict[str, Any],
    hello: codec.HelloContent,
    shared: SharedReader | None,
) -> dict[str, Any]:
    observation = codec.observation_from_message(
        message, intrinsics=hello.intrinsics, shared=shared
    )
    return codec.estimate_message(checked_step(tracker, observation))


def serve(
    tracker: TrackerFactory | TrackerSpec,
    *,
    config: Any = None,
    depth_renderer_factory: Callable[[ObjectModel], DepthRenderer] | None = None,
    stdin_fd: int | None = None,
    stdout_fd: int | None = None,
) -> int:
    """Serves one tracker over the protocol until ``bye`` or the end of stdin.

    Args:
        tracker: a factory ``context -> Tracker`` or a registered spec (built with
            ``create_tracker(spec, context, config)``).
        config: the spec's config (None: its defaults); unused with a factory.
        depth_renderer_factory: builds the depth renderer of a spec that needs one, from the
            object model sent in ``hello``.
        stdin_fd, stdout_fd: descriptors to speak on (default: 0 and the process's stdout,
            which is then moved off descriptor 1).

    Returns:
        The exit status: 0 after ``bye`` or a closed stdin, 1 after an error (sent to the parent
        as an ``error`` message and printed on stderr).
    """
    fd_in, fd_out = _protocol_fds(stdin_fd, stdout_fd)
    _keep_freed_memory()

    def read() -> dict[str, Any] | None:
        payload = read_frame(fd_in)
        return None if payload is None else codec.unpack(payload)

    def send(message: dict[str, Any]) -> None:
        write_frame(fd_out, codec.pack(message))

    try:
        name, build = _factory_of(tracker, config, depth_renderer_factory)
        served, hello, shared = _start(read, build)
        send(codec.ready_message(name, shm=shared is not None))
        while (message := read()) is not None:
            kind = message["type"]
            if kind == "bye":
                break
            if kind == "observation":
                send(_step(served, message, hello, shared))
            elif kind == "reset":
                served.reset(codec.initial_from_reset(message))
                send(codec.ready_message(name))
            else:
                raise ProtocolError(
                    f"message: received type {kind!r}, expected 'reset', 'observation' or 'bye'"
                )
    except Exception as e:  # the parent gets the reason; the traceback goes to stderr
        traceback.print_exc(file=sys.stderr)
        with contextlib.suppress(OSError):
            send(codec.error_message(f"{type(e).__name__}: {e}"))
        return 1
    return 0


def serve_main(
    argv: list[str] | None = None,
    *,
    prog: str = "python -m roft_sim.trackers.process",
    depth_renderer_factory: Callable[[ObjectModel], DepthRenderer] | None = None,
) -> int:
    """``NAME [--config TOML]``: serves the installed tracker plugin ``NAME``."""
    import argparse

    from roft_sim.trackers.base import get_tracker_spec, load_tracker_config

    parser = argparse.ArgumentParser(
        prog=prog,
        description="Serve an installed tracker plugin over the tracker process protocol on "
        "stdin/stdout (docs/process.md). Run it through roft-sim: "
        f'--tracker "process:{prog} NAME"',
    )
    parser.add_argument("name", metavar="NAME", help="registered tracker name (roft-sim trackers)")
    parser.add_argument("--config", metavar="TOML", help="TOML file of the tracker's settings")
    args = parser.parse_args(argv)
    try:
        spec = get_tracker_spec(args.name)
        config = load_tracker_config(spec, args.config)
    except RoftSimError as e:  # unknown name, bad config file
        print(f"{parser.prog}: error: {e}", file=sys.stderr)
        return 2
    return serve(spec, config=config, depth_renderer_factory=depth_renderer_factory)
