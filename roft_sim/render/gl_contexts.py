"""OpenGL contexts shared by the offscreen renderers of one thread.

Mesa's llvmpipe (the CPU OpenGL that CI and most headless machines render with) pays part of its
work once per OpenGL context: on the 640x480 Fast-YCB scene, the first ``MjrContext`` made in a
fresh context (the model's textures uploaded and mipmapped) takes 0.23-0.41 s and a later one in
the same context 0.06-0.12 s, and the first frame drawn 0.07-0.15 s against 0.03-0.07 s
(docs/rendering.md). So :class:`~roft_sim.render.offscreen.OffscreenRenderer` does not make a
context of its own: it draws in its thread's context of its image size, which it acquires here
and releases when closed. A context stays while a renderer uses it and, once none does, is kept
as the thread's idle context for the next renderer of that size (the next sequence a worker
generates, the next run's depth renderer); acquiring a context of another size frees the idle
ones first, so a thread holds at most one context per size in use plus one idle.

Contexts belong to the thread that made them (an OpenGL context is current on one thread at a
time) and to the process: a process forked from one that rendered neither reuses nor frees the
parent's contexts. Renderers that share a context each have their own ``MjrContext``
(framebuffers, textures, meshes), and MuJoCo sets the state it draws with on every render, so a
frame's pixels do not depend on what was drawn in the context before (tested).
"""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass, field

import mujoco

__all__ = ["SharedGlContext", "acquire_gl_context", "free_idle_gl_contexts", "release_gl_context"]


@dataclass(eq=False)
class SharedGlContext:
    """One OpenGL context of a thread and the number of renderers drawing in it."""

    context: mujoco.GLContext
    """MuJoCo's context (EGL or OSMesa, as ``MUJOCO_GL`` chose)."""
    users: int = field(default=0)
    """Renderers that acquired it and have not released it."""

    def make_current(self) -> None:
        """Makes the context current on this thread."""
        self.context.make_current()


_THREAD = threading.local()


def _contexts() -> dict[tuple[int, int, int], SharedGlContext]:
    """This thread's contexts by (id of the process that made it, width, height); the size is
    OSMesa's buffer (EGL's contexts have none)."""
    contexts: dict[tuple[int, int, int], SharedGlContext] | None = getattr(
        _THREAD, "contexts", None
    )
    if contexts is None:
        contexts = _THREAD.contexts = {}
    return contexts


def acquire_gl_context(width_px: int, height_px: int) -> SharedGlContext:
    """This thread's context for images of ``width_px`` x ``height_px``, made current; made (after
    freeing this thread's idle contexts) when the thread has none of that size. Release it
    with :func:`release_gl_context`.

    Raises:
        RuntimeError, mujoco.FatalError: MuJoCo could not make the context (no offscreen
            backend: the caller reports :func:`roft_sim.render.gl_backend.context_error`).
    """
    key = (os.getpid(), int(width_px), int(height_px))
    contexts = _contexts()
    shared = contexts.get(key)
    if shared is None:
        free_idle_gl_contexts()
        shared = SharedGlContext(mujoco.GLContext(key[1], key[2]))
        contexts[key] = shared
    shared.users += 1
    shared.make_current()
    return shared


def release_gl_context(shared: SharedGlContext) -> None:
    """Says a renderer no longer draws in ``shared``; the context is kept (module doc). Call
    once per :func:`acquire_gl_context`, from any thread (a renderer's finaliser may run on
    another); extra calls do nothing."""
    shared.users = max(0, shared.users - 1)


def free_idle_gl_contexts() -> int:
    """Frees this thread's contexts that no renderer uses; returns how many were freed."""
    pid = os.getpid()
    contexts = _contexts()
    idle = [k for k, c in contexts.items() if c.users == 0 and k[0] == pid]
    for key in idle:
        contexts.pop(key).context.free()
    return len(idle)
