"""``python -m latentrl``: the command line (what ``torchrun -m latentrl train ...`` runs on each rank)."""

import sys

from latentrl.app.cli import main

if __name__ == "__main__":
    sys.exit(main())
