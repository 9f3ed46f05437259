"""``python -m pressor`` is the same as the ``pressor`` console script."""

import sys

try:
    from pressor.cli import main

    code = main()
except KeyboardInterrupt:  # Ctrl-C before pressor.cli took the signal over: one line, no traceback
    print("pressor: interrupted by SIGINT", file=sys.stderr)
    code = 130
sys.exit(code)
