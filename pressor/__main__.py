"""``python -m pressor`` is the same as the ``pressor`` console script."""

import sys

from pressor.cli import main

sys.exit(main())
