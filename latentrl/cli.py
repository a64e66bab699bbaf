"""``python -m latentrl.cli`` and ``from latentrl.cli import main``: the command line, kept at its old address.

The parser and the commands live in :mod:`latentrl.app`; this module belongs to that floor.
"""

import sys

from latentrl.app.cli import main

__all__ = ["main"]

if __name__ == "__main__":
    sys.exit(main())
