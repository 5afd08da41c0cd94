#!/usr/bin/env bash
# Sets up roft_sim with its test tools, type-checks it (mypy --strict on roft_sim/, configured in
# pyproject.toml; any error fails the run), checks its import layers (lint-imports: the contracts
# of [tool.importlinter] in pyproject.toml; an import that runs the wrong way fails the run) and
# runs the default test suite (slow tests deselected). Extra arguments go to pytest, e.g.
# `bash scripts/run_tests.sh --run-slow -k flow`.
set -euo pipefail
cd "$(dirname "$0")/.."
# ray: the optional executor is tested too (~80 MB, <10 s); process: msgpack (the tracker
# process protocol); bags: roft-sim bag (mcap, rosbags)
bash scripts/setup.sh dev,ray,process,bags
.venv/bin/python -m mypy
.venv/bin/lint-imports --no-cache
# -n auto: one pytest worker per core (pytest-xdist); `-n 0` runs in this process (for -x, --pdb)
exec .venv/bin/python -m pytest -n auto "$@"
