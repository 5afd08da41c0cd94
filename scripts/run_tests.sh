#!/usr/bin/env bash
# Sets up roft_sim with its test tools and runs the default test suite (slow tests deselected).
# Extra arguments go to pytest, e.g. `bash scripts/run_tests.sh --run-slow -k flow`.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh dev,ray   # ray: the optional executor is tested too (~80 MB, <10 s)
exec .venv/bin/python -m pytest "$@"
