"""The firmware's gate against forged WHEEL_ENCODERS frames that pass Profile 2's CRC (issue #11
point 5; the drives: tests/test_babble_forged_step.py), frame by frame, Python and C fed the
same frames and compared byte for byte on what they transmit.

1. After a mailbox drop the plausibility bound was STEP_PERIODS_MAX (655 s of motion): a forged
   step of 200 periods' travel right after a drop was integrated. It is now bounded by the
   step's periods, a COUNTER cycle and the firmware's own periods since the last sample.
2. On a 16-bit robot the wire's top 8 bits are 0 in every genuine frame; a forged frame whose
   low 16 bits make a plausible step was integrated (the delta is taken in 16 bits). It is now
   refused (IMPLAUSIBLE_STEP) and no part of a restart; the judges' mirror refuses it too.
"""

from __future__ import annotations

import numpy as np

from odocan.firmware import frames as fr
from odocan.firmware.ecu import OdomEcu
from odocan.firmware.errors import ErrorFlag
from odocan.host.judge.lossgate import gated_counts
from odocan.sim import frames as sf
from odocan.sim.cboard import CEcu
from odocan.sim.rig import firmware_params
from odocan.sim.robot import load
from tests.test_ecu import RecordingHal

OTHER_ID = 0x050  # a babbler's ID below WHEEL_ENCODERS
STEP = (10, 12)  # counts per period of the genuine drive (kobuki's bound: 84 per period)


def _script(forged_at: int, forged: tuple[int, int], flood: bool) -> list[list[tuple[int, bytes]]]:
    """Per tick the frames its ISR receives: a genuine drive of 40 periods, at tick
    ``forged_at`` a forged frame with COUNTER in sequence and counts ``forged`` (wire) in place
    of the genuine one (then lost); with ``flood`` 40 frames on another ID after the frame
    before it (the mailbox overflows: the drop is seen at the forged frame's tick)."""
    ticks: list[list[tuple[int, bytes]]] = []
    for k in range(40):
        left, right = (k * STEP[0]) & 0xFFFF, (k * STEP[1]) & 0xFFFF
        data = sf.pack_wheel_encoders(k % 16, *(forged if k == forged_at else (left, right)))
        frames = [(fr.WHEEL_ENCODERS_ID, data)]
        if k == forged_at - 1 and flood:
            frames += [(OTHER_ID, bytes(8))] * 40
        ticks.append(frames)
    return ticks


def _run(ecu: OdomEcu | CEcu, script: list[list[tuple[int, bytes]]]) -> None:
    for frames in script:
        for can_id, data in frames:
            ecu.isr_can_rx(can_id, data)
        ecu.tick()


def _both(script: list[list[tuple[int, bytes]]]) -> tuple[OdomEcu, list[tuple[int, bytes]]]:
    """The Python ECU after the script (kobuki, 16-bit counters) and what it sent; asserts the
    C ECU sent the same bytes."""
    params = firmware_params(load("kobuki"), "exact")
    py_hal, c_hal = RecordingHal(), RecordingHal()
    py = OdomEcu(py_hal, params)
    _run(py, script)
    _run(CEcu(c_hal, params), script)
    assert c_hal.sent == py_hal.sent
    return py, py_hal.sent


def _pose(ecu: OdomEcu) -> tuple[int, int, int]:
    odo = ecu.odometry
    return odo.x_q40_m, odo.y_q40_m, odo.heading_bam64


def _genuine_pose(forged_at: int) -> tuple[int, int, int]:
    """The pose when the frame at ``forged_at`` is merely lost."""
    script = _script(forged_at, (0, 0), flood=False)
    script[forged_at] = []
    ecu, _ = _both(script)
    return _pose(ecu)


def test_a_forged_step_after_a_mailbox_drop_is_refused() -> None:
    at = 20
    forged = ((at - 1) * STEP[0] + 200 * 84) & 0xFFFF, ((at - 1) * STEP[1]) & 0xFFFF
    ecu, _ = _both(_script(at, forged, flood=True))
    assert ecu.mailbox.overflows > 0  # the case: a drop before the forged frame's tick
    assert ecu.encoders.frames_implausible == 1
    assert ecu.health.errors.bits & ErrorFlag.IMPLAUSIBLE_STEP
    assert not ecu.health.errors.bits & ErrorFlag.COUNTER_RESET
    assert _pose(ecu) == _genuine_pose(at)
    # Not the plain step's bound either: 17 periods' travel after the drop (its advance 1, the
    # cycle 16 more, the clock 1) is taken, as frames no one counted (an overrun) may lie between.
    wide = ((at - 1) * STEP[0] + 17 * 84) & 0xFFFF, ((at - 1) * STEP[1]) & 0xFFFF
    ecu, _ = _both(_script(at, wide, flood=True)[: at + 1])  # up to the wide step
    assert ecu.encoders.frames_implausible == 0
    assert not ecu.health.errors.bits & ErrorFlag.IMPLAUSIBLE_STEP


def test_counts_beyond_a_16_bit_counter_are_refused_and_no_restart() -> None:
    at = 20
    plausible = ((at - 1) * STEP[0] + 60) & 0xFFFF, ((at - 1) * STEP[1]) & 0xFFFF
    forged = plausible[0] | 0x3D0000, plausible[1] | 0x3E0000
    ecu, _ = _both(_script(at, forged, flood=False))
    assert ecu.encoders.frames_implausible == 1
    assert ecu.health.errors.bits & ErrorFlag.IMPLAUSIBLE_STEP
    assert not ecu.health.errors.bits & ErrorFlag.COUNTER_RESET
    assert _pose(ecu) == _genuine_pose(at)


def test_the_judges_gate_refuses_counts_beyond_a_16_bit_counter() -> None:
    """``lossgate.gated_counts`` (the judges' mirror): the frame takes the last accepted
    frame's counts; at 24 bits (a 32-bit robot) the same counts are a plain step."""
    left = np.array([0, 10, 0x3D0000 | 80, 30], dtype=np.int64)
    right = np.array([0, 12, 0x3E0000 | 24, 36], dtype=np.int64)
    seq = np.arange(4, dtype=np.int64)
    got_l, got_r, _ = gated_counts(left, right, seq, (84, 84), 16)
    assert got_l.tolist() == [0, 10, 10, 30]
    assert got_r.tolist() == [0, 12, 12, 36]
    wide_l, _, _ = gated_counts(left, right, seq, (0x400000, 0x400000), 24)
    assert wide_l.tolist() == left.tolist()
