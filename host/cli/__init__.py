"""The command line: the parser, shared options, thin subcommands (argparse only)."""

from odocan.host.cli.app import main

__all__ = ["main"]
