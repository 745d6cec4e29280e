"""The ``odocan`` command line: one ``main()``, one module per subcommand."""

from __future__ import annotations

import argparse
import sys


def main(argv: list[str] | None = None) -> int:
    """Parse ``argv`` and run the subcommand; returns the process exit code."""
    parser = argparse.ArgumentParser(prog="odocan", description=__doc__)
    parser.add_argument("--version", action="version", version="odocan 0.1.0")
    parser.parse_args(argv)
    parser.print_help()
    return 0


if __name__ == "__main__":
    sys.exit(main())
