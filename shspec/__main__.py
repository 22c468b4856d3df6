"""``python -m shspec``: the command line (:func:`shspec.cli.main`)."""

import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())
