"""``python -m tests.fleet_paced ARGS...``: the ``odocan`` command line (as ``python -m odocan``)
whose fleets run on ``tests.fleet_run_until.PacedClock``, in this process and in every worker it
spawns: multiprocessing's spawn imports this module again (as ``__mp_main__``) in each worker
before it runs, so the clock is replaced there too.

For a test of a fleet process (``odocan fleet --accel``: its worker compiled) that cannot
monkeypatch it: on the real clock a loaded machine's 1.4 s stall at the first tick halts every
board (``sim.board.HALT_AFTER_S``) and a one-second run ends without the verdicts checked.
"""

from __future__ import annotations

import sys

from odocan.sim import fleet as sim_fleet
from tests.fleet_run_until import PacedClock

setattr(sim_fleet, "RealTimeClock", PacedClock)  # noqa: B010 (not exported: mypy)

if __name__ == "__main__":
    from odocan.host.cli import main

    sys.exit(main())
