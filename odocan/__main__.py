"""``python -m odocan``: the same command line as ``odocan``."""

import sys

try:
    from odocan.host.cli import main

    code = main()
except KeyboardInterrupt:  # Ctrl-C as the command line's package loads, or as ``main`` is entered
    # (a signal is checked on a function's first instruction): one line, no traceback
    print("interrupted (SIGINT): odocan stopped before it finished (while starting)",
          file=sys.stderr)
    code = 130

sys.exit(code)
