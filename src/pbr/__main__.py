"""``python -m pbr ...``: the same command line as the ``pbr`` script (see pbr.cli)."""
import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())
