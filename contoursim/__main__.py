"""``python -m contoursim``: the command line, see :mod:`contoursim.cli`."""

import sys

from .cli import main

sys.exit(main())
