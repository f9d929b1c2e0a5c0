"""``python -m moose.cli``: the ``moose`` command."""
import sys

from . import main

sys.exit(main())
