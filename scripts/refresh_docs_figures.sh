#!/usr/bin/env bash
# Regenerates the measured figures of README.md and docs/: the regions between
# <!-- figure:NAME --> and <!-- /figure:NAME --> and the pictures in docs/images/, each saying on
# which machine and date it was made (scripts/docs_figures.py does the work).
#
#   bash scripts/refresh_docs_figures.sh --list          # the figures
#   bash scripts/refresh_docs_figures.sh --quick         # all of them, small sizes (minutes)
#   bash scripts/refresh_docs_figures.sh                 # all of them, full size (an hour or more)
#   bash scripts/refresh_docs_figures.sh --quick demo    # one figure by name
#
# Run it on an otherwise idle machine (timings are part of what it writes), then review and commit
# the changed Markdown and images. Real YCB meshes and captured motion are used when found
# (--assets / $ROFT_SIM_ASSETS, --trajectories / $ROFT_SIM_TRAJECTORIES, else ../shared/).
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x .venv/bin/roft-sim ] || bash scripts/setup.sh dev
exec .venv/bin/python scripts/docs_figures.py "$@"
