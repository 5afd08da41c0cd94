#!/usr/bin/env bash
# Sets up roft_sim with its test tools, type-checks it (mypy --strict on roft_sim/, configured in
# pyproject.toml; any error fails the run) and runs the default test suite (slow tests
# deselected). Extra arguments go to pytest, e.g. `bash scripts/run_tests.sh --run-slow -k flow`.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh dev,ray   # ray: the optional executor is tested too (~80 MB, <10 s)
.venv/bin/python -m mypy
exec .venv/bin/python -m pytest "$@"
