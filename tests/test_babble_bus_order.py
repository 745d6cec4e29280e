"""A rig log under babble is in bus-time order (issue 11, rule 5): each faulted handle (the
sim's and the firmware's) has its own babbler, and the rig polled one handle after the other,
so one handle's babble up to the tick went out before the other's earlier frames:
``odocan run --robot kobuki --duration 8 --seed 3 --faults babble=2000:0x100,seed=1`` wrote
1144 frames earlier than the frame before them (2000/s from each handle then: ``babble=4000``
since the stated rate is the wire's). The check reads the log's own timestamps."""

from __future__ import annotations

import re
from pathlib import Path

import can
import pytest

from odocan.host.cli.app import main
from odocan.sim.faults import FaultSpec
from tests.fault_rig import FaultRig

_STAMP = re.compile(r"^\((\d+\.\d+)\) ")


def _stamps_s(log: Path) -> list[float]:
    out = []
    for line in log.read_text().splitlines():
        match = _STAMP.match(line)
        if match:
            out.append(float(match.group(1)))
    return out


@pytest.mark.parametrize("faults", ["babble=4000:0x100,seed=1", "babble=1000,seed=2",
                                    "babble=2000:0x100,delay=0.05:7,seed=4"])
def test_babble_log_in_bus_order(tmp_path: Path, faults: str) -> None:
    log = tmp_path / "b.log"
    main(["run", "--robot", "kobuki", "--duration", "1", "--seed", "3", "--faults", faults,
          "--log", str(log)])
    stamps = _stamps_s(log)
    assert len(stamps) > 1000
    back = [k for k in range(1, len(stamps)) if stamps[k] < stamps[k - 1]]
    assert back == [], f"{len(back)} frames earlier than the frame before (first: {back[:1]})"


@pytest.mark.parametrize("spec", ["babble=2000:0x100,seed=1", "babble=1000,delay=0.05:7,seed=4"])
@pytest.mark.parametrize("handle", ["sim", "firmware"])
def test_the_fault_rig_writes_in_bus_order(spec: str, handle: str) -> None:
    """The tests' ``FaultRig`` polled a faulted handle only when its node sent: the babble and the
    held frames due since went out after the other node's later frames (the stall-gate test
    sorted its log by time to mend it). It now brings its handles up to time as the rig does."""
    faults = FaultSpec.parse(spec)
    heard: list[can.Message] = []
    with FaultRig(robot="kobuki", seed=3, sim_faults=faults if handle == "sim" else None,
                  fw_faults=faults if handle == "firmware" else None) as rig:
        rig.observers.append(lambda _tick, frames: heard.extend(frames))
        rig.run(1.0)
    stamps = [m.timestamp for m in heard]
    assert len(stamps) > 1000
    back = [k for k in range(1, len(stamps)) if stamps[k] < stamps[k - 1]]
    assert back == [], f"{len(back)} frames earlier than the frame before (first: {back[:1]})"
