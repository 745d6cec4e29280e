"""A staged APPLY 2 ticks after a stall the firmware re-primes after, its COUNTER_RESET already
latched by an earlier stall (issue #11, ``host.judge.cutreprime``, ``acrosscut.earlier_word``).

``test_staged_apply_sweep``'s drive (pmir reset at tick ``REBOOT``; X, Y, HEADING and APPLY
sent 2 ticks after the stall resumed), with a 6 s stall 1 s after the reset first: it latches
COUNTER_RESET, so the cut's word (clear before the stall, set after) is never said. Measured
(the lockstep ``FaultRig``): the square halted 4 s or 8 s before the APPLY, ``analyze`` FAILs
the correct firmware on DISTANCE (2.38 mm beyond, position 2.88 mm: the step into the re-prime
frame taken); without the latching stall, and on the spin, it PASSes. Not fixed here: pinned
as strict xfails with the figure (the cut's re-prime needs the unsure rule of
``stallreprime``: both hypotheses tried on the samples after the APPLY).
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

import can
import pytest

from odocan.firmware import frames as fr
from odocan.firmware.errors import ErrorMask
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from odocan.sim.board import TICK_S
from odocan.sim.scenarios import get_scenario
from tests import host_frames as hf
from tests.fault_rig import FaultRig, open_virtual
from tests.test_reprime_apply import AFTER_TICKS, REBOOT
from tests.test_staged_reboot import PMIR, _written

CUT_STALL = REBOOT + 1000  # the stall the APPLY follows (tick)
TARGET = (5000, -3000, 10000)  # X, Y (0.1 mm), HEADING (BAM16)


@cache
def drive(scenario: str, halted: int, latch: bool) -> tuple[can.Message, ...]:
    """The reset, (``latch``) a 6 s stall from tick REBOOT + 100, the stall of ``halted``
    ticks from ``CUT_STALL``, the APPLY 2 ticks after it resumed, 2 s driven after."""
    apply_at = CUT_STALL + halted + 2
    heard: list[can.Message] = []
    sends = ((fr.SetPoseField.X, TARGET[0]), (fr.SetPoseField.Y, TARGET[1]),
             (fr.SetPoseField.HEADING, TARGET[2]), (fr.SetPoseField.APPLY, 0))
    with FaultRig(scenario=get_scenario(scenario, PMIR, duration_s=60.0)) as rig:
        rig.halted = lambda k: ((latch and REBOOT + 100 < k <= REBOOT + 700)
                                or CUT_STALL < k <= CUT_STALL + halted)
        tool = open_virtual(rig.channel)

        def host(k: int) -> None:
            if k == REBOOT:
                rig.board.reboot()
                while rig.fw_bus.recv(0) is not None:  # the reset clears the receive FIFO
                    pass
            if k == apply_at:
                for counter, (field, value) in enumerate(sends):
                    tool.send(can.Message(
                        arbitration_id=fr.ODOM_SET_POSE_ID, is_extended_id=False,
                        data=hf.pack_odom_set_pose(counter, field, value, ErrorMask()),
                        timestamp=k * TICK_S))

        rig.observers.append(lambda _k, got: heard.extend(got))
        rig.before_board.append(host)
        try:
            rig.run((CUT_STALL + halted + AFTER_TICKS) * TICK_S)
        finally:
            tool.shutdown()
    return tuple(heard)


def _passed(messages: tuple[can.Message, ...], path: Path) -> bool:
    return bool(analyze(read_log(_written(messages, path)), PMIR, "exact").report["passed"])


@pytest.mark.parametrize(("scenario", "halted", "latch"),
                         [("square", 400, False), ("spin", 400, True), ("spin", 800, True)])
def test_the_correct_firmware_passes(scenario: str, halted: int, latch: bool,
                                     tmp_path: Path) -> None:
    assert _passed(drive(scenario, halted, latch), tmp_path / "right.log")


@pytest.mark.xfail(strict=True, reason="latched COUNTER_RESET before a stall an APPLY follows: "
                   "the cut's re-prime not taken, DISTANCE 2.38 mm beyond (measured)")
@pytest.mark.parametrize("halted", [400, 800])
def test_latched_before_the_cut_stall_the_correct_firmware_passes(halted: int,
                                                                   tmp_path: Path) -> None:
    assert _passed(drive("square", halted, True), tmp_path / "right.log")
