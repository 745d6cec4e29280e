"""An ambiguous recorder hole after FRAME_TOTALS pages of the life (issue #11, rule 3: a FAIL
must never blame a correct firmware; ``host.judge.livechoice``).

``test_gap_placement``'s evidenceless hole (frames 185-186 cut from the log of a fast robot,
the step from 184 to 187 ambiguous), with the firmware's FRAME_TOTALS pages in the log: one
page 1.5 s before the hole, or one every 0.5 s (ENC_E2E pages at 160 and 210, none inside the
hole: the pages prove neither frames taken in it, ``holetaken``, nor the hole missed). The whole
log's judge chooses by the next pose; the live judges re-primed (a FRAME_TOTALS page heard:
pages might yet prove the hole), so the firmware that took the frames one by one FAILed the
monitor and the bridge by 2 cm.

The re-prime's pose is this file's own float64 odometry (``independent_checker._Odometry``)
without the steps into 185-187; nothing of the judges' computes what is expected.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import POSITION_LSB_M, analyze
from odocan.host.judge.samples import HEADING_LSB_RAD
from tests.synth_log import synthesize
from tests.test_gap_placement import FAST, _cut, _drive, hole_log
from tests.test_judge_campaign import profile_of
from tests.test_stall_bound import _live

ONE_PAGE = frozenset({30})  # one FRAME_TOTALS page, 1.5 s before the hole: it proves nothing
ROTATION = frozenset(range(30, 801, 50))  # one every 0.5 s, ENC_E2E pages at 160 and 210


@pytest.mark.parametrize("firmware", ["took", "reprimed", "heading_off"])
@pytest.mark.parametrize("pages", ["one", "rotation"])
def test_an_ambiguous_hole_the_pages_heard_do_not_decide_is_chosen_as_whole(
        tmp_path: Path, pages: str, firmware: str) -> None:
    """FRAME_TOTALS pages heard before the hole, none deciding it: the firmware that took the
    frames passes every judge (before: POSE WRONG live, 22.5 mm off the re-primed reference),
    the one that re-primed too; HEADING 2 LSB off from 187 on FAILs every judge."""
    path = hole_log(tmp_path, firmware, ONE_PAGE if pages == "one" else ROTATION)
    _judged_alike(path, right=firmware != "heading_off")


@pytest.mark.parametrize("firmware", ["took", "heading_off"])
def test_a_second_ambiguous_hole_within_the_hold(tmp_path: Path, firmware: str) -> None:
    """Two such holes 0.5 s apart (frames 185-186 and 235-236 cut, no FRAME_TOTALS page): the
    firmware that took both passes every judge; one whose HEADING is 2 LSB off from 237 on
    FAILs every judge (before: PASS live, the second hole a new start from the pose after it
    while the first one's choice was held)."""
    d_left, d_right = _drive(FAST, 800, 0, 0.015625, 0.0)
    synth = synthesize(profile_of(FAST), "euler", d_left, d_right,
                       heading_bias_lsb=dict.fromkeys(range(237, 801), 2)
                       if firmware == "heading_off" else None)
    path = _cut(synth, [(185, 2), (235, 2)]).write(tmp_path / "holes.log")
    _judged_alike(path, right=firmware == "took")


def _judged_alike(path: Path, right: bool) -> None:
    """``analyze`` and the live judges (the monitor's model, the bridge) PASS the log when
    ``right``, else FAIL it on its heading, each with one reference start (the choices, never
    a new start)."""
    result = analyze(read_log(path), profile_of(FAST), "euler")
    assert result.passed is right, result.report["onboard_vs_reference"]
    monitor, bridge, end_s = _live(profile_of(FAST), "euler", path)
    assert (monitor.health(end_s)["state"] == "POSE WRONG") is not right, monitor.health(end_s)
    for tracker in (monitor.tracker, bridge.tracker):
        assert (tracker.vs_reference.max_dheading_rad > HEADING_LSB_RAD) is not right
        assert (tracker.wrongs.count > 0) is not right
        assert tracker.max_beyond_allowance_m <= POSITION_LSB_M
        assert tracker.reference_starts == 1
