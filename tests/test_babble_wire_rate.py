"""``--faults babble=RATE`` puts RATE frames per second on the wire, as a CAN tool's interactive
generator means "2000 frames/s".

``odocan run`` faults both the motor controller's and the firmware's handles with one spec, and
each handle had a babbler of its own at RATE: ``babble=2000`` put about 4000 frames/s on the
wire (19 787 frames of ID 0x050 in 5 s). ``faultspec.two_handles`` now splits the rate in half
between them (two Poisson streams of RATE / 2 are one of RATE; halving is exact, so a spec of
2 * RATE replays the old runs frame for frame). Counted in the log, by ID.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

from odocan.host.cli.app import main
from odocan.sim.faultspec import FaultSpec, two_handles

DURATION_S = 5


def test_the_stated_babble_rate_is_the_wire_rate(tmp_path: Path) -> None:
    log, report = tmp_path / "babble.log", tmp_path / "babble.json"
    assert main(["run", "--duration", str(DURATION_S), "--faults", "babble=2000:0x050",
                 "--log", str(log), "--report", str(report)]) == 0
    babbled = sum(" 050#" in line for line in log.read_text().splitlines())
    print(f"\n{babbled} frames of ID 0x050 in {DURATION_S} s at babble=2000")
    assert 0.95 * 2000 * DURATION_S < babbled < 1.05 * 2000 * DURATION_S  # ~10 000 +- 100 (1 sd)
    assert json.loads(report.read_text())["inputs"]["faults"] == "babble=2000:0x050,seed=0"


def test_two_handles_split_the_rate_and_draw_their_own_faults() -> None:
    spec = FaultSpec.parse("drop=0.01,babble=3000:0x050:2:0.5,busoff=1:0.5,seed=7")
    sim, fw = two_handles(spec)
    assert (sim.babble, fw.babble) == (1500.0, 1500.0)
    assert (sim.seed, fw.seed) == (7, 8)
    assert sim == replace(spec, babble=1500.0)  # every other fault as given, on each
    assert fw == replace(sim, seed=8)
