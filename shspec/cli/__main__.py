"""``python -m shspec.cli``: the command line (:func:`shspec.cli.main`)."""

import sys

from . import main

if __name__ == "__main__":
    sys.exit(main())
