"""The command line: the parser, shared options, thin subcommands (argparse only).

``main`` imports ``app`` only when called, so that ``python -m odocan.host.cli.app`` runs the
module once, without runpy's "found in sys.modules" warning on stderr.
"""

from __future__ import annotations

import os
import sys

__all__ = ["main"]

# numpy's OpenBLAS starts a thread per core when numpy loads; they spin-wait for work no odocan
# command gives them (no large matrix product anywhere: 0.08 s of CPU per process for nothing),
# and a dot product split across them sums in another order, so np.dot of more than ~10^4
# elements (the start fit's sums, ``reference_path.block_dot``) differs in its last bits from
# one machine's core count to another's. One thread: the same bits on every machine, and less
# CPU. A user's own setting is kept; set before numpy is imported (nothing here imports it).
BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "1")


def main(argv: list[str] | None = None) -> int:
    """The ``odocan`` command (``odocan.host.cli.app.main``)."""
    os.environ.setdefault(*BLAS_THREADS)
    try:
        from odocan.host.cli.app import main as app_main
    except KeyboardInterrupt:  # Ctrl-C while the command line loads: one line, no traceback
        print("interrupted (SIGINT): odocan stopped before it finished (while starting)",
              file=sys.stderr)
        return 130  # 128 + SIGINT (app's EXIT_SIGNAL_BASE; app is what did not load)
    return app_main(argv)
