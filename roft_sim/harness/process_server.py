"""``python -m roft_sim.harness.process_server NAME [--config TOML]``: serves a tracker plugin
over the tracker process protocol, with a MuJoCo depth renderer for trackers that need one.

The renderer is built in the child, lazily on its first render, from the mesh that ``hello``
carries. This entry point lives in the harness layer because the trackers layer may not import
:mod:`roft_sim.render`; ``python -m roft_sim.trackers.process NAME`` serves the trackers that
need no renderer.
"""

from __future__ import annotations

import os
import sys

from roft_sim.harness.inputs import LazyDepthRenderer, mujoco_depth_renderer
from roft_sim.records import DepthRenderer, ObjectModel
from roft_sim.trackers.process import serve_main

__all__ = ["main"]


def _lazy_renderer(model: ObjectModel) -> DepthRenderer:
    from roft_sim.render.gl_backend import select_gl_backend

    select_gl_backend(os.environ)  # before MuJoCo is imported (on the first render)
    return LazyDepthRenderer(mujoco_depth_renderer, model)


def main(argv: list[str] | None = None) -> int:
    """Serves ``NAME`` (the command-line arguments) and returns the exit status."""
    return serve_main(
        argv,
        prog="python -m roft_sim.harness.process_server",
        depth_renderer_factory=_lazy_renderer,
    )


if __name__ == "__main__":
    sys.exit(main())
