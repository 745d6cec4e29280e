"""``python -m odocan``: the same command line as ``odocan``."""

import sys

from odocan.host.cli import main

sys.exit(main())
