"""``python -m odocan``: the same command line as ``odocan``."""

import sys

try:
    from odocan.host.cli import main
except KeyboardInterrupt:  # Ctrl-C as the command line's package loads: one line, no traceback
    print("interrupted (SIGINT): odocan stopped before it finished (while starting)",
          file=sys.stderr)
    sys.exit(130)

sys.exit(main())
