"""``python -m roft_sim`` runs the ``roft-sim`` command line."""

import sys

from roft_sim.cli import main

if __name__ == "__main__":
    sys.exit(main())
