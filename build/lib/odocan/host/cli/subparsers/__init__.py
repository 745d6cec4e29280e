"""One module per ``odocan`` subcommand: ``add_subparser(subparsers)`` and ``_do_<cmd>(args)``."""
