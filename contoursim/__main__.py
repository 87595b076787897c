"""``python -m contoursim``: the command line, see :mod:`contoursim.cli`."""

from .cli import run

run()
