"""A babbling node on a bit-timed bus: which messages starve, and what the report says of it.

``odocan run -b 125000 --faults babble=3000`` for 3 simulated s: 3000 frames/s on the wire, 1500
from each of the sim's and the firmware's controllers (random IDs, 10 % error frames, which win
every arbitration), which with odocan.dbc's own traffic asks more than the 125 kbit/s wire can
carry. Arbitration then serves the low identifiers: WHEEL_ENCODERS (0x100) still gets nearly
every frame through, the low-priority status and truth messages (0x380, 0x700) starve in their
transmit buffers.

The report names them (``bus.starved``, a STARVED line in the summary, frames late and never
sent per message). The E2E layer cannot: a frame that waits is not lost, so its sequence counters
show no gap (asserted: the bus section, not the E2E counts, is where starvation shows).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

DURATION_S = 3


def test_babble_starves_the_low_priorities_and_the_report_says_so(tmp_path: Path) -> None:
    report_path = tmp_path / "babble.json"
    done = subprocess.run(
        [sys.executable, "-m", "odocan", "run", "-b", "125000", "--duration", str(DURATION_S),
         "--faults", "babble=3000", "--report", str(report_path)],
        capture_output=True, text=True, timeout=300,
    )
    assert done.returncode in (0, 1), done.stderr
    report = json.loads(report_path.read_text())
    bus = report["bus"]
    rows = {row["name"]: row for row in bus["messages"]}
    assert bus["load"] > 0.97  # the wire never idles
    # 10 ms encoders: nearly all through, a few past their deadline (error frames beat them)
    assert rows["WHEEL_ENCODERS"]["frames"] >= 0.95 * DURATION_S * 100
    assert rows["WHEEL_ENCODERS"]["still_queued"] == 0
    for name, per_s in (("ODOM_STATUS", 20), ("SIM_TRUTH", 30)):
        row = rows[name]
        assert row["frames"] < 0.2 * DURATION_S * per_s, name
        assert row["still_queued"] > 0.5 * DURATION_S * per_s, name
        assert name in bus["starved"]
        assert report["e2e"][name]["lost"] == 0  # waiting is not losing: E2E sees nothing
    other = [row for name, row in rows.items() if name.startswith("(other")]
    assert other
    assert other[0]["frames"] > 1000
    assert other[0]["name"] not in bus["starved"]
    assert "STARVED past their deadline" in done.stdout
    assert "ODOM_STATUS" in done.stdout.split("STARVED past their deadline")[1].splitlines()[0]
