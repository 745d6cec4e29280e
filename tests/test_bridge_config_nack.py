"""A config command the firmware NACKs must not change the bridge's reference (found by the trial).

The bridge took a `cmd/config`'s parameters for its live reference when it SENT the frames, not
when the firmware acknowledged the APPLY: `cmd/config` with a robot the firmware refuses
(result `nacked`, reason INCONSISTENT) left the firmware on its old parameters (right, its pose
on the truth) while the bridge's reference drove on with the refused ones: `pose_wrong` true,
1.7 m off, a correct firmware blamed. Here a real Python firmware answers the bridge's frames;
an independent float64 dead reckoning of the counts (written here) says where the pose must be.
"""

from __future__ import annotations

import json
import math
from typing import Any, cast

import pytest

from odocan.firmware import frames as fr
from odocan.firmware.odometry import Odometry
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.bridge import _Robot
from odocan.sim.contract import database
from tests.bridge_pair import D_LEFT, D_RIGHT, KOBUKI, PERIOD_S, Board, bridged_robot

DB = database()

# A robot the firmware refuses as a whole (one count turns it 450 deg): NACK INCONSISTENT
REFUSED = {"id": "c2", "counts_per_rev": 4, "wheel_radius_left_m": 0.05,
           "wheel_radius_right_m": 0.05, "wheelbase_m": 0.01, "counter_bits": 16,
           "integrator": "exact"}


def _dead_reckoned(periods: int) -> tuple[float, float]:
    """Independent float64: the exact arc of a constant step, ``periods`` times from (0, 0, 0)."""
    per_count_l = 2 * math.pi * KOBUKI.wheel_radius_left_m / KOBUKI.counts_per_rev
    per_count_r = 2 * math.pi * KOBUKI.wheel_radius_right_m / KOBUKI.counts_per_rev
    ds = (D_LEFT * per_count_l + D_RIGHT * per_count_r) / 2
    dth = (D_RIGHT * per_count_r - D_LEFT * per_count_l) / KOBUKI.wheelbase_m
    x = y = th = 0.0
    for _ in range(periods):
        x += ds / dth * (math.sin(th + dth) - math.sin(th))
        y -= ds / dth * (math.cos(th + dth) - math.cos(th))
        th += dth
    return x, y


def _drive_with_config(config: dict[str, object], channel: str) -> tuple[_Robot, Board]:
    """100 periods, ``config`` sent through the bridge to the firmware (taken after the next
    encoder frame), 300 periods more."""
    with bridged_robot(channel) as (bridge, listener):
        board = Board(bridge, listener)
        for _ in range(100):
            board.period()
        answer = bridge.on_command("config", json.dumps(config).encode())
        assert answer[0][1]["result"] == "accepted", answer
        board.period(late=True)  # the firmware answers the APPLY: ODOM_ACK
        assert any(m.arbitration_id == fr.ODOM_CONFIG_ID for m in board.commands)
        for _ in range(299):
            board.period()
    return bridge, board


def test_a_nacked_config_leaves_the_reference_on_the_firmware_s_parameters() -> None:
    bridge, board = _drive_with_config(REFUSED, "test-bridge-config-nack")
    assert [(r["id"], r["result"], r["reason"]) for r in board.results] == [
        ("c2", "nacked", "INCONSISTENT")]
    x_m, y_m = _dead_reckoned(399)  # the first frame primes the firmware: 399 steps
    pose = board.ecu.odometry
    assert abs(pose.x_q40_m / 2.0**40 - x_m) < 1e-4
    assert abs(pose.y_q40_m / 2.0**40 - y_m) < 1e-4
    tracker = bridge.telemetry.tracker
    assert tracker.geometry == Geometry.of(KOBUKI)
    wrongs = tracker.wrongs.as_dict()
    assert wrongs["episodes"] == 0, wrongs

    # and parameters the firmware ACKs are the reference's from then on
    wider = {**REFUSED, "id": "c1", "counts_per_rev": KOBUKI.counts_per_rev,
             "wheel_radius_left_m": KOBUKI.wheel_radius_left_m,
             "wheel_radius_right_m": KOBUKI.wheel_radius_right_m, "wheelbase_m": 0.25,
             "integrator": "rk2"}
    bridge, board = _drive_with_config(wider, "test-bridge-config-ack")
    assert [(r["id"], r["result"]) for r in board.results] == [("c1", "acked")]
    tracker = bridge.telemetry.tracker
    assert tracker.geometry.wheelbase_m == 0.25
    assert tracker.integrator == "rk2"
    assert tracker.wrongs.as_dict()["episodes"] == 0


# --- two configs back to back (the second's parameters replaced the first's before its ACK) ---
WIDER = {"id": "c1", "counts_per_rev": KOBUKI.counts_per_rev,
         "wheel_radius_left_m": KOBUKI.wheel_radius_left_m,
         "wheel_radius_right_m": KOBUKI.wheel_radius_right_m, "wheelbase_m": 0.25,
         "counter_bits": 16, "integrator": "exact"}


class _ConfigBoard(Board):
    """``Board`` noting the period of each ODOM_CONFIG APPLY the firmware answered (cantools)."""

    def __init__(self, bridge: _Robot, listener: Any) -> None:
        super().__init__(bridge, listener)
        self.apply_periods: list[int] = []

    def firmware_frame(self, can_id: int, data: bytes) -> None:
        if can_id == fr.ODOM_ACK_ID:
            s = cast(dict[str, Any], DB.decode_message(can_id, data, decode_choices=False))
            if s["REQUEST_ID"] == fr.ODOM_CONFIG_ID and s["REQUEST_FIELD"] == 15:
                self.apply_periods.append(round(self.t_s / PERIOD_S))
        super().firmware_frame(can_id, data)


def _two_configs(first: dict[str, object], second: dict[str, object], channel: str
                 ) -> tuple[_Robot, _ConfigBoard]:
    """100 periods, ``first`` and ``second`` published at once, 300 periods more."""
    with bridged_robot(channel) as (bridge, listener):
        board = _ConfigBoard(bridge, listener)
        for _ in range(100):
            board.period()
        for config in (first, second):
            answer = bridge.on_command("config", json.dumps(config).encode())
            assert answer[0][1]["result"] == "accepted", answer
        for _ in range(300):
            board.period()
    return bridge, board


def _dead_reckoned_with(steps: list[float]) -> tuple[float, float]:
    """Independent float64: the exact arc of the constant step, one wheelbase (m) a step."""
    per_count_l = 2 * math.pi * KOBUKI.wheel_radius_left_m / KOBUKI.counts_per_rev
    per_count_r = 2 * math.pi * KOBUKI.wheel_radius_right_m / KOBUKI.counts_per_rev
    ds = (D_LEFT * per_count_l + D_RIGHT * per_count_r) / 2
    x = y = th = 0.0
    for wheelbase_m in steps:
        dth = (D_RIGHT * per_count_r - D_LEFT * per_count_l) / wheelbase_m
        x += ds / dth * (math.sin(th + dth) - math.sin(th))
        y -= ds / dth * (math.cos(th + dth) - math.cos(th))
        th += dth
    return x, y


def test_two_configs_back_to_back_each_taken_by_the_reference_at_its_own_ack(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The first (wheelbase 0.25 m) is ACKed, the second (a robot the firmware refuses) NACKed:
    the reference must run on the first from its APPLY on (it took the second's at the first's
    ACK and kept it: POSE WRONG on a correct firmware). A firmware that ACKs a second config
    but keeps the first's constants must still be judged wrong."""
    bridge, board = _two_configs(WIDER, REFUSED, "test-bridge-two-configs")
    assert [(r["id"], r["result"]) for r in board.results] == [("c1", "acked"), ("c2", "nacked")]
    applied = board.apply_periods[0]  # drained before that period's encoder frame
    x_m, y_m = _dead_reckoned_with([KOBUKI.wheelbase_m] * (applied - 1) + [0.25] * (400 - applied))
    pose = board.ecu.odometry  # the firmware is right (independent float64) ...
    assert abs(pose.x_q40_m / 2.0**40 - x_m) < 1e-4
    assert abs(pose.y_q40_m / 2.0**40 - y_m) < 1e-4
    tracker = bridge.telemetry.tracker  # ... and the judge says so
    assert tracker.geometry.wheelbase_m == 0.25
    assert tracker.wrongs.as_dict()["episodes"] == 0, tracker.wrongs.as_dict()

    constants: list[Any] = []  # a wrong firmware: it ACKs the second but keeps the first's
    real = Odometry.reconfigure

    def kept_first(self: Odometry, consts: Any) -> None:
        constants.append(consts)
        real(self, constants[0])

    monkeypatch.setattr(Odometry, "reconfigure", kept_first)
    second = {**WIDER, "id": "c2", "wheelbase_m": 0.28}
    bridge, board = _two_configs(WIDER, second, "test-bridge-two-configs-swap")
    assert len(constants) == 2
    assert [(r["id"], r["result"]) for r in board.results] == [("c1", "acked"), ("c2", "acked")]
    assert bridge.telemetry.tracker.geometry.wheelbase_m == 0.28
    assert bridge.telemetry.tracker.wrongs.as_dict()["episodes"] >= 1  # FAIL: it kept 0.25 m
