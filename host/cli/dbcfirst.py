"""``--dbc PATH`` governs the whole command: the judges' bus facts are PATH's, not odocan's.

The judges read their bus facts (cycle times, COUNTER laps, page numbers ...) once, when they are
imported, of the DBC at ``sim.contract.DBC_PATH`` (``ODOCAN_DBC``; ``host.protocol.busfacts``).
A command that decoded with ``--dbc OTHER`` while its judges held odocan's DBC's cycles judged a
firmware speaking OTHER (encoders at 20 ms, say) against 10 ms periods: a correct one FAILed.

So ``follow_named_dbc`` runs before anything of odocan's DBC is read: when the command line names
``--dbc PATH`` (``analyze``, ``monitor``) and the process has not read a DBC yet, PATH becomes
the process's DBC (``ODOCAN_DBC``: its child processes follow it too). A PATH that cannot be read
or parsed is left to the command, which refuses it in one line. Where the judges were loaded
already (a second ``main()`` in one interpreter), ``require_judges_follow`` refuses a DBC whose
facts differ from theirs, naming the fact, rather than judge with mixed constants.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from odocan.host.protocol.dbcplan import DatabaseSpec

DBC_ENV = "ODOCAN_DBC"  # sim.contract reads it once, at import
DBC_COMMANDS = frozenset({"analyze", "monitor"})  # their judges follow --dbc
# what reads the process's DBC when imported: once one is, the DBC is this process's for good
READERS_OF_THE_DBC = ("odocan.sim.contract", "odocan.host.protocol.busfacts")


def named_dbc(argv: list[str]) -> str | None:
    """The ``--dbc`` value of ``argv`` (``--dbc PATH`` or ``--dbc=PATH``, before any ``--``; the
    last one wins, as argparse's), or None."""
    found: str | None = None
    for i, arg in enumerate(argv):
        if arg == "--":
            break
        if arg == "--dbc" and i + 1 < len(argv):
            found = argv[i + 1]
        elif arg.startswith("--dbc="):
            found = arg.removeprefix("--dbc=")
    return found


def follow_named_dbc(argv: list[str], command: str | None) -> None:
    """Make ``--dbc PATH`` the process's DBC before any judge reads one (module docstring)."""
    path = named_dbc(argv) if command in DBC_COMMANDS else None
    if path is None or any(name in sys.modules for name in READERS_OF_THE_DBC):
        return
    from odocan.host.protocol.dbcfacts import judge_facts, missing_signals
    from odocan.host.protocol.dbcplan import load_plan
    from odocan.sim import SHIPPED_DBC

    try:
        plan = load_plan(Path(path))
        judge_facts(plan)  # parses, and holds every fact the judges read
    except Exception:
        return
    if missing_signals(plan, load_plan(SHIPPED_DBC)) is not None:
        return  # the judges read the signals by name, some at import: the command refuses it
    os.environ[DBC_ENV] = str(Path(path).resolve())


def require_judges_follow(named: DatabaseSpec, path: Path) -> None:
    """Refuse (``DbcFactError``, one line) the DBC at ``path`` (parsed: ``named``) when a fact
    the judges read differs from the one they were loaded with in this process."""
    from odocan.host.protocol.dbcfacts import DbcFactError, first_difference
    from odocan.host.protocol.dbcplan import default_plan

    difference = first_difference(named, default_plan())
    if difference is not None:
        from odocan.sim.contract import DBC_PATH

        raise DbcFactError(
            f"--dbc {path}: {difference} in the judges' DBC ({DBC_PATH}), read when this "
            f"process began; run the command in a process of its own, or set {DBC_ENV}"
        )
