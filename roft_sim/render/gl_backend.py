"""Choosing MuJoCo's offscreen OpenGL backend (EGL, else OSMesa) before ``import mujoco``.

MuJoCo reads ``MUJOCO_GL`` once, when it is imported; PyOpenGL reads ``PYOPENGL_PLATFORM``. This
module probes each backend in a short subprocess (a failed GL initialisation can leave a process
unusable), sets both variables in the mapping it is given (``os.environ`` from the CLI or from
pytest), and explains how to install a backend when none works. Library code that imports
roft_sim's rendering without having chosen gets the same choice (:func:`prepare_mujoco_gl`).
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from collections.abc import Mapping, MutableMapping
from concurrent.futures import Future

from roft_sim.errors import RenderBackendError

__all__ = [
    "BACKENDS",
    "INSTALL_HINT",
    "select_gl_backend",
    "start_gl_probe",
    "probe_gl_backend",
    "require_gl_backend",
    "prepare_mujoco_gl",
    "context_error",
]

BACKENDS = ("egl", "osmesa")
"""Backends tried, in order."""

INSTALL_HINT = (
    "install a CPU OpenGL backend: on Debian/Ubuntu run "
    "'sudo apt-get install -y libegl1 libopengl0 libgl1-mesa-dri' (EGL) or "
    "'sudo apt-get install -y libosmesa6' (OSMesa), then set MUJOCO_GL=egl or MUJOCO_GL=osmesa"
)

_PROBE_SCRIPT = (
    "import mujoco\n"
    "xml = '<mujoco><worldbody><geom size=\"1\"/></worldbody></mujoco>'\n"
    "m = mujoco.MjModel.from_xml_string(xml)\n"
    "r = mujoco.Renderer(m, 8, 8)\n"
    "r.render()\n"
    "r.close()\n"
)


_PROBES: dict[str, Future[str | None]] = {}
"""Each backend's probe, run once per process (on a thread: :func:`start_gl_probe`)."""
_PROBES_LOCK = threading.Lock()


def _probe_future(backend: str) -> Future[str | None]:
    """The probe of ``backend``, started on a daemon thread on the first call."""
    with _PROBES_LOCK:
        future = _PROBES.get(backend)
        if future is None:
            future = _PROBES[backend] = Future()
            threading.Thread(
                target=_run_probe, args=(backend, future), name="roft-sim-gl-probe", daemon=True
            ).start()
    return future


def _run_probe(backend: str, future: Future[str | None]) -> None:
    try:
        future.set_result(_probe_in_subprocess(backend))
    except BaseException as e:  # handed to whoever waits for the result
        future.set_exception(e)


def _probe(backend: str) -> str | None:
    """None when ``backend`` renders in a fresh process, else the error it printed (probed
    once per process; waits for a probe :func:`start_gl_probe` started)."""
    return _probe_future(backend).result()


def start_gl_probe(environ: Mapping[str, str]) -> None:
    """Starts probing the backend :func:`select_gl_backend` tries first (``MUJOCO_GL``, else
    EGL) in the background and returns at once, so that the probe's subprocess (about a second:
    it imports MuJoCo and renders) runs while the caller imports and loads its inputs; the
    selection waits for it. Does nothing when MuJoCo is already imported."""
    if "mujoco" not in sys.modules:
        _probe_future(environ.get("MUJOCO_GL") or BACKENDS[0])


def _probe_in_subprocess(backend: str) -> str | None:
    """None when ``backend`` renders in a fresh process, else the error it printed."""
    env = {"MUJOCO_GL": backend, "PYOPENGL_PLATFORM": backend}
    full_env = {**os.environ, **env}
    try:
        result = subprocess.run(
            [sys.executable, "-c", _PROBE_SCRIPT],
            env=full_env,
            capture_output=True,
            text=True,
            timeout=120,
        )
    except subprocess.TimeoutExpired:
        return f"{backend}: the probe timed out"
    if result.returncode == 0:
        return None
    lines = [ln for ln in result.stderr.strip().splitlines() if ln.strip()]
    return f"{backend}: {lines[-1] if lines else f'exit code {result.returncode}'}"


def select_gl_backend(environ: MutableMapping[str, str]) -> str | None:
    """Sets ``MUJOCO_GL``/``PYOPENGL_PLATFORM`` in ``environ`` to the first working backend.

    A backend the user already chose (``MUJOCO_GL`` set) is kept without probing. Returns the
    backend, or None when none works (rendering will then fail with :func:`require_gl_backend`'s
    message).
    """
    chosen = environ.get("MUJOCO_GL")
    if chosen:
        environ.setdefault("PYOPENGL_PLATFORM", chosen)
        return chosen
    for backend in BACKENDS:
        if _probe(backend) is None:
            environ["MUJOCO_GL"] = backend
            environ.setdefault("PYOPENGL_PLATFORM", backend)
            return backend
    return None


def probe_gl_backend(backend: str | None = None) -> str | None:
    """None when offscreen rendering works, else a message naming the problem and the fix.

    Args:
        backend: the backend to check; default: the one in ``MUJOCO_GL``, else any of
            :data:`BACKENDS`.
    """
    if backend:
        candidates: tuple[str, ...] = (backend,)
    elif os.environ.get("MUJOCO_GL"):
        candidates = (os.environ["MUJOCO_GL"],)
    else:
        candidates = BACKENDS
    problems = []
    for b in candidates:
        problem = _probe(b)
        if problem is None:
            return None
        problems.append(problem)
    return "; ".join(problems) + f". To fix, {INSTALL_HINT}"


def require_gl_backend(environ: MutableMapping[str, str]) -> str:
    """Like :func:`select_gl_backend`, but raises when no backend works.

    Raises:
        RenderBackendError: neither EGL nor OSMesa initialises; the message says what to install.
    """
    backend = select_gl_backend(environ)
    problem = probe_gl_backend(backend) if backend else probe_gl_backend()
    if backend is None or problem is not None:
        raise RenderBackendError(f"offscreen rendering is unavailable ({problem})")
    return backend


def prepare_mujoco_gl() -> None:
    """Chooses ``MUJOCO_GL`` for library users, before MuJoCo is imported.

    Called where roft_sim imports MuJoCo (by the ``roft_sim.render`` package, before any of its
    modules is imported), so that a script that never set ``MUJOCO_GL`` renders offscreen
    instead of failing on MuJoCo's default (GLFW, which needs a display). Does nothing when the
    variable is set or MuJoCo is already imported (its choice is then fixed). ``MUJOCO_GL`` is
    MuJoCo's own variable: the one environment variable roft_sim reads outside its CLI.
    """
    if "mujoco" not in sys.modules and not os.environ.get("MUJOCO_GL"):
        select_gl_backend(os.environ)


def context_error(error: Exception) -> RenderBackendError:
    """The error to raise when MuJoCo cannot create its OpenGL context."""
    chosen = os.environ.get("MUJOCO_GL")
    how = (
        f"MUJOCO_GL={chosen} did not work"
        if chosen
        else "MuJoCo was imported before an offscreen backend was chosen"
    )
    return RenderBackendError(
        f"cannot create an offscreen OpenGL context ({how}: {error}). Set MUJOCO_GL=egl or "
        "MUJOCO_GL=osmesa before importing mujoco, or call "
        "roft_sim.render.gl_backend.select_gl_backend(os.environ) first; if neither backend works, "
        f"{INSTALL_HINT}"
    )
