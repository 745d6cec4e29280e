"""The live hold's judging (``host.judge.livesettle``) imports the frame collector only when a
hold is judged (issue #13: a fleet's bridge starts without what a clean drive never uses)."""

from __future__ import annotations

import subprocess
import sys


def test_the_bridge_imports_no_frame_collector_until_a_hold() -> None:
    """Before: ``host.mqtt.telemetry`` imported ``host.io.collector`` through ``livesettle``."""
    code = ("import sys, odocan.host.mqtt.telemetry, odocan.host.judge.monitor; "
            "print('odocan.host.io.collector' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"
