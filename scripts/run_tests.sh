#!/usr/bin/env bash
# Sets up roft_sim with its test tools, checks its import layers (lint-imports: the contracts of
# [tool.importlinter] in pyproject.toml; an import that runs the wrong way fails the run), and
# runs the default test suite (slow tests deselected) with the type check beside it (mypy
# --strict on roft_sim/, configured in pyproject.toml; any error fails the run). Extra arguments
# go to pytest, e.g. `bash scripts/run_tests.sh --run-slow -k flow`.
set -euo pipefail
cd "$(dirname "$0")/.."
# ray: the optional executor is tested too (~80 MB, <10 s); process: msgpack (the tracker
# process protocol); bags: roft-sim bag (mcap, rosbags)
bash scripts/setup.sh dev,ray,process,bags
.venv/bin/lint-imports --no-cache
# mypy (one core, ~45 s cold) runs beside pytest so that the run keeps every core busy; its
# report follows the tests' and any error fails the run.
mypy_log=$(mktemp)
.venv/bin/python -m mypy >"$mypy_log" 2>&1 &
mypy_pid=$!
trap 'kill "$mypy_pid" 2>/dev/null || true; rm -f "$mypy_log"' EXIT
# -n auto: one pytest worker per core (pytest-xdist); `-n 0` runs in this process (for -x, --pdb)
tests_status=0
.venv/bin/python -m pytest -n auto --dist worksteal "$@" || tests_status=$?
mypy_status=0
wait "$mypy_pid" || mypy_status=$?
echo "mypy:"
cat "$mypy_log"
if [ "$mypy_status" -ne 0 ]; then
    echo "run_tests: mypy found errors (above); fix them or run .venv/bin/python -m mypy" >&2
    exit 1
fi
exit "$tests_status"
