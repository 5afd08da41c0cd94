"""``python -m roft_sim.trackers.process NAME [--config TOML]``: serves a tracker plugin.

Trackers that need a depth renderer (ROFT) are served by ``python -m
roft_sim.harness.process_server NAME`` instead: building MuJoCo's renderer is above the trackers
layer.
"""

from __future__ import annotations

import sys

from roft_sim.trackers.process.server import serve_main

if __name__ == "__main__":
    sys.exit(serve_main())
