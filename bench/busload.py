"""odocan.dbc's bus load and worst slack at the usual bitrates, and the analysis' own speed.

For each bitrate the utilization (all messages; cyclic ones only) and the least slack D - R by the
revised analysis of Davis et al. (2007), under two assumptions for the four event messages (no
GenMsgCycleTime in the DBC): the default (sporadic at the DBC's shortest cycle, 10 ms) and
``--sporadic-ms 100``. Sender ticks are the defaults (shortest cycle per sender), queue jitter 0.
Then the time one analysis of the DBC takes. Prints figures; asserts nothing.
Run: ``.venv/bin/python bench/busload.py``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from odocan.host.judge.schedulability import NS_PER_MS, analyse_bus, messages_from_dbc  # noqa: E402
from odocan.sim.contract import database  # noqa: E402

BITRATES = (125_000, 250_000, 500_000, 1_000_000)


def _row(bitrate: int, sporadic_ms: str | None) -> str:
    load = analyse_bus(messages_from_dbc(database(), sporadic_ms=sporadic_ms), bitrate)
    name, slack_ns = load.worst_slack()
    cyclic = load.as_dict()["utilization_cyclic"]
    slack = "unbounded" if slack_ns is None else f"{slack_ns / NS_PER_MS:+8.3f} ms"
    verdict = "OK  " if load.schedulable else "MISS"
    return (
        f"{bitrate:>9}  {load.utilization:6.1%}  {cyclic:6.1%}  {verdict}  "
        f"least slack {slack} ({name})"
    )


def main() -> None:
    """Print the table for both sporadic assumptions, then the analysis time."""
    for label, sporadic_ms in (("event messages at 10 ms (default)", None), ("at 100 ms", "100")):
        print(f"odocan.dbc, {label}:")
        print("  bit/s    util.   cyclic  verdict")
        for bitrate in BITRATES:
            print(_row(bitrate, sporadic_ms))
        print()
    messages = messages_from_dbc(database())
    runs = 200
    start = time.perf_counter()
    for _ in range(runs):
        analyse_bus(messages, 125_000)
    per_run_ms = (time.perf_counter() - start) / runs * 1e3
    print(f"one analysis of odocan.dbc (12 messages) at 125 kbit/s: {per_run_ms:.2f} ms")


if __name__ == "__main__":
    main()
