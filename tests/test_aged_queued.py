"""Encoder frames that waited behind a babbler are no controller restart (the "aged less than
the silence" rule, firmware/encoders.py ``_aged_uptime``).

A babbler below WHEEL_ENCODERS' ID holds a bit-timed bus for more than a second: the motor
controller's encoder frames wait in its transmit buffer, and the first one the firmware hears
after the silence was sampled right after the last one it accepted: its CTRL_UPTIME is as old,
not aged by the silence. It is the E2E successor of that frame (waiting is not losing): the
firmware (Python and C, bit for bit) and every judge (analyze whole and streamed, the monitor)
must take it for what it is, not re-prime on it as a restart (which lost the motion of the
silence: 3.5 mm off the truth, a correct firmware FAILed).
"""

from __future__ import annotations

import itertools
from pathlib import Path

import can
import pytest

from odocan.firmware.ecu import MAX_WHEEL_SPEED_MM_S
from odocan.firmware.errors import ErrorFlag
from odocan.host.io.logs import iter_log, read_log
from odocan.host.judge.analysis import analyze
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.reference import Geometry
from odocan.host.judge.stream import StreamE2E, StreamEncoders, StreamReference
from odocan.host.protocol.decode import BulkDecoder
from odocan.sim.contract import database
from odocan.sim.faults import FaultSpec
from odocan.sim.faultspec import two_handles
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.robot import load
from tests.dbc_typed import decode, number

DB = database()
STATUS = DB.get_message_by_name("ODOM_STATUS")
ENCODERS = DB.get_message_by_name("WHEEL_ENCODERS")
BABBLES_S = (0.5, 1.0)  # babble from 2 s for that long: encoder frames wait 1.4 s, 2.7 s
BITRATE = 125_000
DURATION_S = 5.0
SILENCE_S = 1.2  # a bus gap the old rule aged by 1 s or more ((120 - 16) // 100 periods)


def babble_log(path: Path, firmware: str, babble_s: float) -> Path:
    """pmir's random drive on a 125 kbit/s bus with a babbler on ID 0x050 (1500 frames/s from each
    controller from 2 s, ``babble_s`` long), as ``odocan run --faults`` drives it (the drive run
    ahead, the firmware's handle faulted with the next seed): the candump log."""
    spec, fw_spec = two_handles(FaultSpec.parse(f"babble=3000:0x050:2:{babble_s},seed=3"))
    config = RigConfig(load("pmir"), faults=spec, fw_faults=fw_spec,
                       bitrate=BITRATE, seed=3, lookahead=True,
                       firmware=firmware, duration_s=DURATION_S)
    with LockstepRig(config, [can.Logger(path)]) as rig:
        rig.run(DURATION_S)
    return path


def waited_frames(path: Path) -> list[tuple[float, int, int, int, int]]:
    """(bus gap s, COUNTER before, COUNTER after, CTRL_UPTIME before, after) of each pair of
    consecutive WHEEL_ENCODERS frames more than ``SILENCE_S`` apart on the bus (cantools)."""
    frames = [(m.timestamp, decode(DB, ENCODERS.frame_id, m.data))
              for m in can.LogReader(path) if m.arbitration_id == ENCODERS.frame_id]
    out = []
    for (t0, a), (t1, b) in itertools.pairwise(frames):
        if t1 - t0 > SILENCE_S:
            out.append((t1 - t0, int(number(a["COUNTER"])), int(number(b["COUNTER"])),
                        int(number(a["CTRL_UPTIME"])), int(number(b["CTRL_UPTIME"]))))
    return out


def counter_resets(path: Path) -> int:
    """ODOM_STATUS summaries whose ERROR_MASK has COUNTER_RESET (decoded by cantools)."""
    n = 0
    for msg in can.LogReader(path):
        if msg.arbitration_id == STATUS.frame_id and msg.data[1] >> 4 == 0:
            mask = int(number(decode(DB, STATUS.frame_id, msg.data)["ERROR_MASK"]))
            n += bool(mask & int(ErrorFlag.COUNTER_RESET))
    return n


def streamed_reprimes(path: Path) -> list[int]:
    """The encoder frames the streamed reference (``stream.StreamReference``, fed in chunks of
    64 frames as ``analyze --stream`` feeds it) re-primed on."""
    e2e, numbering = StreamE2E(DB), StreamEncoders(BulkDecoder(DB))
    reference = StreamReference(Geometry.of(load("pmir")), "exact", 16, MAX_WHEEL_SPEED_MM_S)
    for chunk in iter_log(path, chunk_frames=64):
        reference.feed(numbering.feed(chunk, e2e.feed(chunk)))
    return reference.reprimed


@pytest.mark.parametrize("babble_s", BABBLES_S)
def test_frames_queued_behind_a_babbler_are_no_restart_for_the_firmware_nor_any_judge(
    tmp_path: Path, babble_s: float
) -> None:
    """Before the fix the 0.5 s babble's frames were a restart for the firmware (COUNTER_RESET;
    3.5 mm off the truth) and every judge, the 1 s babble's for every judge (the firmware's
    mailbox had dropped frames of the burst: its rule stood down)."""
    python = babble_log(tmp_path / "python.log", "python", babble_s)
    c = babble_log(tmp_path / "c.log", "c", babble_s)
    assert python.read_bytes() == c.read_bytes()
    waited = waited_frames(python)
    print(f"\nwaited: {waited}")
    assert waited  # a silence of the bus the old rule took for 1 s of age or more
    for _gap_s, before, after, up_before, up_after in waited:
        assert after == (before + 1) % 16  # the E2E successor: nothing lost
        assert up_after <= up_before  # not aged by the silence: it waited
    assert counter_resets(python) == 0  # the firmware never re-primed
    profile = load("pmir")
    whole = analyze(read_log(python), profile).report
    assert whole["passed"], whole["onboard_vs_reference"]
    assert [e for e in whole["events"] if e["kind"] == "counter_restart"] == []
    assert streamed_reprimes(python) == []  # analyze streamed (its reference; the CLI
    # judges a queued life whole: stream_analysis.NotStreamable)
    monitor = BusMonitor(profile)
    for msg in can.LogReader(python):
        monitor.feed(msg, now_s=msg.timestamp)
    assert monitor.tracker.counter_restarts == 0
