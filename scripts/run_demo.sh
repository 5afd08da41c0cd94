#!/usr/bin/env bash
# Sets up roft_sim and runs the main job on the embedded default (no files beyond pip/apt
# packages): see `roft-sim demo --help`. Extra arguments go to `roft-sim demo`.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
exec .venv/bin/roft-sim demo --out out/demo --overwrite "$@"
