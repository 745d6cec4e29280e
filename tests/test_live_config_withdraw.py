"""A config two senders left in doubt, settled by the PROFILE page on the other tool's robot: the
withdrawal takes back the largest errors and the loss allowance's maximum too (issue #11,
``host.judge.liveconfigdoubt.settle_config``), as a late-told reboot's does
(``PoseTracker.withdraw_from``; ``tests/test_allowance_withdraw.py``).

The drive of ``tests.test_two_config_senders``: the other tool's ODOM_CONFIG frames first, both
from COUNTER 0, so the firmware runs the other tool's wheelbase (0.25 m; the float64 dead
reckoning there says so) while the bridge judged the samples up to the PROFILE page with its
own 0.27 m. Found before: ``settle_config`` withdrew the POSE WRONG episodes only; the bridge's
end verdict PASSed the correct firmware, the fleet's (``watched_verdict``: the largest heading
error and the largest position error beyond the allowance) FAILed it, "heading vs reference
3.026 mrad". A firmware running neither tool's wheelbase still FAILs both.
"""

from __future__ import annotations

import json

import pytest

from odocan.host.mqtt.endverdict import end_verdict
from odocan.host.mqtt.fleetjudge import watched_verdict
from odocan.host.mqtt.telemetry import RobotTelemetry
from tests.bridge_pair import bridged_robot
from tests.test_bridge_foreign_config import PERIODS
from tests.test_two_config_senders import MINE, _drive, _Lying, _other_frames, _runs_wheelbase


def _verdicts(telemetry: RobotTelemetry) -> tuple[str, str]:
    """The fleet's end verdict (``watched_verdict``) and the bridge's."""
    fleet = watched_verdict(telemetry, 0, None)["verdict"]
    return fleet, end_verdict(telemetry).verdict


def test_the_fleet_passes_the_correct_firmware_the_profile_page_settled() -> None:
    bridge, board = _drive("test-config-withdraw", 0, other_first=True)
    _runs_wheelbase(board, 0.25)  # the other tool's: the firmware is right
    tracker = bridge.telemetry.tracker
    assert "the firmware runs the other tool's" in [
        e["detail"] for e in bridge.telemetry.events if e["kind"] == "config"][-1]
    assert _verdicts(bridge.telemetry) == ("PASS", "PASS")
    assert tracker.vs_reference.max_dheading_rad < 1e-4
    assert tracker.max_beyond_allowance_m < 1e-4


@pytest.mark.parametrize("other_first", [True, False])
def test_a_firmware_running_neither_wheelbase_fails_the_fleet(other_first: bool) -> None:
    with bridged_robot(f"test-config-withdraw-lying-{other_first}") as (bridge, listener):
        board = _Lying(bridge, listener, _other_frames(0), other_first)
        for _ in range(100):
            board.period()
        bridge.on_command("config", json.dumps(MINE).encode())
        for _ in range(PERIODS - 100):
            board.period()
    assert _verdicts(bridge.telemetry) == ("FAIL", "FAIL")
