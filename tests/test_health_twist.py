"""ODOM_TWIST is right after any gap, and the judge checks it like the pose.

The lockstep rig loses the sim's frames for a while (bus-off of MOTOR_CTRL's controller); the
firmware's LINEAR_VEL after the gap is checked against the speed the test computes itself from the
wheel counts on the bus (decoded with cantools), and ``analyze`` must pass it. A firmware double
whose twist uses the old dt (the 4-bit COUNTER advance) must fail the judge.
"""

from __future__ import annotations

import io
import math
from collections.abc import Callable

import numpy as np
import pytest
from rich.console import Console

from odocan.firmware.ecu import OdomEcu
from odocan.host.io.logs import FrameArrays, FrameCollector
from odocan.host.judge.analysis import Tolerance, analyze
from odocan.host.report.summary import print_summary
from odocan.sim.contract import database
from odocan.sim.faults import FaultSpec
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.robot import load
from tests.dbc_typed import numbers

PMIR = load("pmir")


def drive(busoff_s: float, patch: Callable[[OdomEcu], None] | None = None) -> FrameArrays:
    """6 s straight on pmir; MOTOR_CTRL and SIM are bus-off from 3 s for ``busoff_s``."""
    collector = FrameCollector()
    faults = FaultSpec.parse(f"busoff=3:{busoff_s}")
    config = RigConfig(PMIR, "exact", "straight", 1, faults=faults, duration_s=6.0)
    with LockstepRig(config, [collector]) as rig:
        if patch is not None:
            patch(rig.board.ecu)
        rig.run()
    return collector.arrays()


def gap_and_twist(frames: FrameArrays) -> tuple[int, float, float, float]:
    """(periods of the longest encoder gap, the first LINEAR_VEL naming a frame j after it,
    the mean speed over the firmware's step to j from the counts, one count over that span),
    speeds in m/s, decoded with cantools."""
    db = database()
    enc, twist = [], []
    for t, can_id, data in zip(frames.timestamp_s, frames.can_id, frames.data, strict=True):
        if can_id == 0x100:
            s = numbers(db, int(can_id), bytes(data))
            enc.append((t, int(s["COUNTER"]), int(s["LEFT_COUNT"]), int(s["RIGHT_COUNT"])))
        elif can_id == 0x202:
            s = numbers(db, int(can_id), bytes(data))
            twist.append((t, int(s["ENC_COUNTER"]), float(s["LINEAR_VEL"])))
    times = np.array([e[0] for e in enc])
    k = int(np.argmax(np.diff(times))) + 1  # the first encoder frame after the gap
    periods = round((times[k] - times[k - 1]) / 0.01)
    named = {c: j for j, (_, c, _, _) in enumerate(enc[k : k + 3], k)}
    after, j = next((v, named[c]) for t, c, v in twist if t > times[k] and c in named)
    # The firmware's step ends at j and starts at the frame it took before j: k - 1 when j is k,
    # or when frame k repeated the COUNTER of k - 1 (a gap of 16 n periods: E2E REPEATED).
    i = k - 1 if j == k or (j == k + 1 and periods % 16 == 0) else j - 1
    m_per_count = 2 * math.pi * PMIR.wheel_radius_left_m / PMIR.counts_per_rev
    counts = (enc[j][2] - enc[i][2] + enc[j][3] - enc[i][3]) % (1 << 16)
    span_s = times[j] - times[i]
    return periods, after, counts / 2 * m_per_count / span_s, m_per_count / span_s


@pytest.mark.parametrize("busoff_s", [0.17, 0.32, 1.01])
def test_linear_vel_after_a_gap_is_the_speed(busoff_s: float) -> None:
    frames = drive(busoff_s)
    periods, after, speed, one_count = gap_and_twist(frames)
    assert periods >= 16
    assert after == pytest.approx(speed, abs=one_count + 0.0005)  # + LINEAR_VEL's rounding
    result = analyze(frames, PMIR)
    twist = result.report["onboard_twist_vs_reference"]
    assert twist["samples"] > 200
    assert twist["passed"]
    assert result.passed


def _old_dt(ecu: OdomEcu) -> None:
    """The twist of the 4-bit COUNTER advance: 16 lost frames look like none."""
    update = ecu.twist.update

    def wrong(periods: int) -> None:
        update((periods % 16) or 1)

    ecu.twist.update = wrong  # type: ignore[method-assign]


def test_the_judge_fails_a_twist_from_the_wrong_dt() -> None:
    frames = drive(1.01, _old_dt)
    result = analyze(frames, PMIR)
    twist = result.report["onboard_twist_vs_reference"]
    assert twist["max_linear_excess_mps"] > 1.0
    assert not twist["passed"]
    assert not result.passed
    assert result.report["onboard_vs_reference"]["max_position_error_m"] <= 1e-4  # pose right


def test_the_verdict_line_names_the_twist() -> None:
    """A twist-only FAIL read "FAIL: on-board vs reference within 0.1 mm ...; ODOM_TWIST ...",
    as if the pose had failed (issue #11, rule 6): it names the twist first, the pose met."""
    frames = drive(1.01, _old_dt)
    result = analyze(frames, PMIR)
    console = Console(file=io.StringIO(), width=200)
    print_summary(result.report, Tolerance(), console, title="t")
    last = console.file.getvalue().strip().splitlines()[-1]  # type: ignore[attr-defined]
    assert last.startswith("FAIL: ODOM_TWIST outside the reference's speeds by up to ")
    assert last.endswith("(the pose criterion is met: on-board vs reference within 0.1 mm "
                         "and 0.09587 mrad)")
