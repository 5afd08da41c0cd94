"""The OpenGL backend probe runs once per process and can start in the background."""

from __future__ import annotations

import sys
import threading
import time

from roft_sim.render import gl_backend


def test_start_gl_probe_returns_at_once_and_the_selection_waits_for_the_same_probe(monkeypatch):
    calls: list[str] = []
    release = threading.Event()

    def slow_probe(backend: str) -> str | None:
        calls.append(backend)
        release.wait(10.0)
        return None

    monkeypatch.setattr(gl_backend, "_probe_in_subprocess", slow_probe)
    monkeypatch.setattr(gl_backend, "_PROBES", {})
    monkeypatch.delitem(sys.modules, "mujoco", raising=False)  # as before MuJoCo's import
    t0 = time.perf_counter()
    gl_backend.start_gl_probe({"MUJOCO_GL": "fakegl"})
    assert time.perf_counter() - t0 < 1.0
    assert not gl_backend._PROBES["fakegl"].done()  # still probing in the background
    release.set()
    assert gl_backend.probe_gl_backend("fakegl") is None  # waits for that probe
    assert gl_backend.probe_gl_backend("fakegl") is None
    assert calls == ["fakegl"]  # once


def test_a_failed_probe_is_reported_by_the_selection(monkeypatch):
    monkeypatch.setattr(gl_backend, "_probe_in_subprocess", lambda backend: f"{backend}: no")
    monkeypatch.setattr(gl_backend, "_PROBES", {})
    problem = gl_backend.probe_gl_backend("fakegl")
    assert problem is not None and problem.startswith("fakegl: no")
