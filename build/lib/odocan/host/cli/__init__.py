"""The command line: the parser, shared options, thin subcommands (argparse only).

``main`` imports ``app`` only when called, so that ``python -m odocan.host.cli.app`` runs the
module once, without runpy's "found in sys.modules" warning on stderr.
"""

from __future__ import annotations

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    """The ``odocan`` command (``odocan.host.cli.app.main``)."""
    from odocan.host.cli.app import main as app_main

    return app_main(argv)
