"""``python -m arshadow``: the command line (:func:`arshadow.cli.main`)."""

import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())
