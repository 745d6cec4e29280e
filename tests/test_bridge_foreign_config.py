"""The bridge follows the configs the firmware applies, not the ones it sent (issue #11).

Holes the bridge had, for it took a config's parameters from its own ``cmd/config`` when the
firmware ACKed the APPLY (the monitor followed the bus, ``host.judge.liveconfig``; now both do
through it):

* **another tool's config** (the ``odocan`` CLI, a user's script) on the bus while a bridge
  judges: the bridge kept the old geometry, so it failed a correct firmware reconfigured to a
  wheelbase of 0.25 m, and passed one that ACKed the config but kept its 0.23 m;
* **its own config interrupted by a reboot**: the pages ACKed, the MCU reset (RAM lost: the
  staged pages with it), then the APPLY, which the new firmware ACKs with nothing staged: it
  runs its build's robot. The bridge took the parameters it had sent;
* **a config lost with a reboot**: the firmware applied the bridge's config, then rebooted: it
  comes up with its build's robot (the config was in its RAM), while the bridge and the monitor
  judged its new life with the config's wheelbase; and the other way, a config the new firmware
  takes in its very first tick, ACKed before its boot summary tells the reboot, is its own.

A real Python firmware (``OdomEcu`` on kobuki, ``tests.bridge_pair``) answers; a monitor
(``BusMonitor``) hears the same bus, the bridge's own command frames too. Independent of
the judges: ODOM_ACK, ODOM_STATUS PROFILE and ODOM_POSE_X/Y decoded with cantools, and a float64
dead reckoning written here (``tests.test_bridge_config_nack``) says where the pose must be.
"""

from __future__ import annotations

import json
from typing import Any, TypeVar, cast

import can
import pytest

from odocan.firmware import frames as fr
from odocan.firmware.ecu import OdomEcu
from odocan.firmware.odometry import Odometry
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.bridge import _Robot
from odocan.host.protocol.commands import CommandEncoder
from odocan.sim.contract import database
from odocan.sim.rig import firmware_params
from tests.bridge_pair import KOBUKI, PERIOD_S, bridged_robot
from tests.test_bridge_config_nack import WIDER, _ConfigBoard, _dead_reckoned_with

DB = database()
APPLY = 15  # ODOM_CONFIG PARAM / ODOM_ACK REQUEST_FIELD of APPLY (the DBC's VAL_)
PROFILE_PAGE = 6  # ODOM_STATUS PAGE of PROFILE (the DBC's VAL_)
PERIODS = 400


def _decoded(can_id: int, data: bytes) -> dict[str, Any]:
    return cast(dict[str, Any], DB.decode_message(can_id, data, decode_choices=False))


class _Watched(_ConfigBoard):
    """``_ConfigBoard`` keeping, with cantools, every ODOM_ACK (its period), every PROFILE_CRC
    (its period) and the on-board poses the firmware sent; a ``BusMonitor`` hears every frame
    on the bus (the bridge's command frames too)."""

    def __init__(self, bridge: _Robot, listener: Any) -> None:
        super().__init__(bridge, listener)
        self.acks: list[tuple[int, dict[str, Any]]] = []
        self.profile_crcs: list[tuple[int, int]] = []
        self.poses: dict[int, dict[str, float]] = {}  # by encoder period: X, Y (m)
        self.monitor = BusMonitor(KOBUKI, "exact")

    def firmware_frame(self, can_id: int, data: bytes) -> None:
        k = round(self.t_s / PERIOD_S)
        if can_id == fr.ODOM_ACK_ID:
            self.acks.append((k, _decoded(can_id, data)))
        elif can_id == fr.ODOM_STATUS_ID and _decoded(can_id, data)["PAGE"] == PROFILE_PAGE:
            self.profile_crcs.append((k, int(_decoded(can_id, data)["PROFILE_CRC"])))
        elif can_id in (fr.ODOM_POSE_X_ID, fr.ODOM_POSE_Y_ID):
            s = _decoded(can_id, data)
            named = k - ((k - int(s["ENC_COUNTER"])) & 0xF)  # the period of the frame it names
            self.poses.setdefault(named, {}).update(
                {n: float(v) for n, v in s.items() if n in ("X", "Y")})
        super().firmware_frame(can_id, data)

    def to_bridge(self, can_id: int, data: bytes) -> list[dict[str, Any]]:
        self._to_monitor(can_id, data)
        return super().to_bridge(can_id, data)

    def command_frame(self, msg: can.Message) -> None:
        self._to_monitor(msg.arbitration_id, bytes(msg.data))  # the bridge's own, on the wire
        super().command_frame(msg)

    def _to_monitor(self, can_id: int, data: bytes) -> None:
        self.monitor.feed(can.Message(timestamp=self.t_s, arbitration_id=can_id,
                                      is_extended_id=False, data=data), now_s=self.t_s)

    def other_tool(self, frames: list[tuple[int, bytes]]) -> None:
        """Frames another tool puts on the bus: the firmware, the bridge and the monitor."""
        for can_id, data in frames:
            self.to_bridge(can_id, data)
            self.ecu.isr_can_rx(can_id, data)


def _config_frames(config: dict[str, object]) -> list[tuple[int, bytes]]:
    """``config`` as the ``odocan`` CLI puts it on the bus (its own E2E counters)."""
    command = CommandEncoder().encode("config", json.dumps(config).encode())
    return [(f.can_id, f.data) for f in command.frames]


def _other_tool_drive(channel: str) -> tuple[_Robot, _Watched]:
    """100 periods, WIDER (wheelbase 0.25 m) sent by another tool, 299 periods more."""
    with bridged_robot(channel) as (bridge, listener):
        board = _Watched(bridge, listener)
        for _ in range(100):
            board.period()
        board.other_tool(_config_frames(WIDER))
        for _ in range(PERIODS - 100):
            board.period()
    return bridge, board


def _events(bridge: _Robot, kind: str) -> list[str]:
    """The ``kind`` events the bridge's retained ``status`` carries."""
    _, payload = bridge.telemetry.status()
    return [e["detail"] for e in payload["events"] if e["kind"] == kind]


def _wrongs(bridge: _Robot, board: _Watched) -> tuple[int, int]:
    """The POSE WRONG episodes of the bridge and of the monitor."""
    return (bridge.telemetry.tracker.wrongs.as_dict()["episodes"],
            board.monitor.tracker.wrongs.as_dict()["episodes"])


def _assert_pose(board: _Watched, primed: int, applied: int | None) -> None:
    """The firmware's last whole pose (cantools) is the float64 dead reckoning from its
    power-up primed on the encoder frame of period ``primed``: 0.23 m a step, 0.25 m from the
    period ``applied`` on (None: never)."""
    named = max(k for k, xy in board.poses.items() if len(xy) == 2)
    wheelbases_m = [0.25 if applied is not None and k >= applied else KOBUKI.wheelbase_m
                    for k in range(primed + 1, named + 1)]
    x_m, y_m = _dead_reckoned_with(wheelbases_m)
    pose = board.poses[named]
    assert named >= PERIODS - 3
    assert abs(pose["X"] - x_m) < 1e-3, (pose, x_m, y_m)
    assert abs(pose["Y"] - y_m) < 1e-3, (pose, x_m, y_m)


def test_the_bridge_follows_a_config_another_tool_applies() -> None:
    bridge, board = _other_tool_drive("test-bridge-foreign-config")
    config_acks = [s for _, s in board.acks if s["REQUEST_ID"] == fr.ODOM_CONFIG_ID]
    assert [s["RESULT"] for s in config_acks] == [0] * 7  # six PARAMs and the APPLY ACKed
    _assert_pose(board, 0, board.apply_periods[0])
    telemetry = bridge.telemetry  # the firmware is right: PASS, the config an event
    assert telemetry.tracker.geometry.wheelbase_m == 0.25
    assert _wrongs(bridge, board) == (0, 0), telemetry.tracker.wrongs.as_dict()
    assert _events(bridge, "config") == [
        "config applied: 2578 counts/rev, wheel radii 0.035/0.035 m, wheelbase 0.25 m, exact: "
        "reference restarted"]
    assert telemetry.profile.section is not None
    assert telemetry.profile.section["verdict"] == "OK", telemetry.profile.section
    assert board.results == []  # not the bridge's command: no cmd/result


def test_a_firmware_that_acks_another_tool_s_config_but_keeps_its_wheelbase_fails(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(Odometry, "reconfigure", lambda self, consts: None)
    bridge, board = _other_tool_drive("test-bridge-foreign-config-kept")
    assert [s["RESULT"] for _, s in board.acks] == [0] * 7  # cantools: all ACKed ...
    _assert_pose(board, 0, None)  # ... yet 0.23 m all along
    bridge_wrongs, monitor_wrongs = _wrongs(bridge, board)
    assert bridge_wrongs >= 1  # FAIL, both judges
    assert monitor_wrongs >= 1


# --- the bridge's own config, the MCU reset between its pages and its APPLY ---
REBOOT_AT, APPLY_AT = 120, 150  # periods


class _RebootBoard(_Watched):
    """The bridge's APPLY held back (a slow bus) until ``APPLY_AT``; the MCU reset at
    ``REBOOT_AT`` (a new ``OdomEcu``: RAM lost). ``kept``: a wrong firmware that keeps its
    staged config across the reset."""

    def __init__(self, bridge: _Robot, listener: Any, kept: bool) -> None:
        super().__init__(bridge, listener)
        self.kept = kept
        self.held: list[can.Message] = []

    def command_frame(self, msg: can.Message) -> None:
        if msg.arbitration_id == fr.ODOM_CONFIG_ID and \
                _decoded(msg.arbitration_id, bytes(msg.data))["PARAM"] == APPLY:
            self.held.append(msg)
            return
        super().command_frame(msg)

    def period(self, *, late: bool = False) -> None:
        k = round(self.t_s / PERIOD_S)
        if k == REBOOT_AT:
            staged = self.ecu.commands._staged_config
            self.ecu = OdomEcu(self.hal, firmware_params(KOBUKI, "exact"))
            if self.kept:
                self.ecu.commands._staged_config = staged
        if k == APPLY_AT:
            for msg in self.held:
                super().command_frame(msg)
        super().period(late=late)


Board = TypeVar("Board", "_RebootBoard", "_LostBoard")


def _config_drive(channel: str, board_of: type[Board], kept: bool) -> tuple[_Robot, Board]:
    """100 periods, the bridge's cmd/config WIDER, then to ``PERIODS`` on a board of
    ``board_of`` (which resets the MCU on its way; ``kept``: a firmware that keeps what the
    reset should take)."""
    with bridged_robot(channel) as (bridge, listener):
        board = board_of(bridge, listener, kept)
        for _ in range(100):
            board.period()
        answer = bridge.on_command("config", json.dumps(WIDER).encode())
        assert answer[0][1]["result"] == "accepted", answer
        for _ in range(PERIODS - 100):
            board.period()
    return bridge, board


def _reset_checked(board: _RebootBoard) -> None:
    """cantools: the six PARAMs ACKed before the reset, the APPLY alone after it, ACKed."""
    acks = [(k, s["REQUEST_FIELD"], s["RESULT"]) for k, s in board.acks
            if s["REQUEST_ID"] == fr.ODOM_CONFIG_ID]
    assert [(k < REBOOT_AT, field, result) for k, field, result in acks] == [
        *[(True, field, 0) for field in (0, 1, 2, 3, 4, 5)], (False, APPLY, 0)]
    assert REBOOT_AT < board.apply_periods[0] <= APPLY_AT + 1


def test_a_bridge_config_interrupted_by_a_reboot_leaves_the_build_s_robot() -> None:
    bridge, board = _config_drive("test-bridge-config-reboot", _RebootBoard, kept=False)
    _reset_checked(board)
    before = [crc for k, crc in board.profile_crcs if k < 100]
    after = [crc for k, crc in board.profile_crcs if k > board.apply_periods[0]]
    assert before
    assert set(after) == {before[-1]}  # the build's robot, as at first
    _assert_pose(board, REBOOT_AT, None)  # 0.23 m from its reset on
    assert [(r["id"], r["result"]) for r in board.results] == [("c1", "acked")]
    telemetry = bridge.telemetry  # the judge follows what the firmware runs: PASS
    assert telemetry.reboots == 1
    assert telemetry.tracker.geometry.wheelbase_m == KOBUKI.wheelbase_m
    assert _wrongs(bridge, board) == (0, 0), telemetry.tracker.wrongs.as_dict()
    assert telemetry.profile.section is not None
    assert telemetry.profile.section["verdict"] == "OK", telemetry.profile.section


def test_a_firmware_that_keeps_the_config_staged_before_its_reboot_fails() -> None:
    bridge, board = _config_drive("test-bridge-config-reboot-kept", _RebootBoard, kept=True)
    _reset_checked(board)
    applied = board.apply_periods[0]
    before = [crc for k, crc in board.profile_crcs if k < 100]
    after = [crc for k, crc in board.profile_crcs if k > applied]
    assert after
    assert before[-1] not in after  # cantools: it runs another robot ...
    _assert_pose(board, REBOOT_AT, applied)  # ... the staged 0.25 m
    bridge_wrongs, monitor_wrongs = _wrongs(bridge, board)
    assert bridge_wrongs >= 1  # FAIL, both judges
    assert monitor_wrongs >= 1


# --- the bridge's config applied, then the MCU reset: the config was in its RAM ---
LOST_AT = 250  # period of the reset


class _LostBoard(_Watched):
    """The MCU reset at ``LOST_AT``; ``kept``: a wrong firmware that comes up with the robot
    it was configured to (its parameters, PROFILE CRC and odometry constants kept)."""

    def __init__(self, bridge: _Robot, listener: Any, kept: bool) -> None:
        super().__init__(bridge, listener)
        self.kept = kept

    def period(self, *, late: bool = False) -> None:
        if round(self.t_s / PERIOD_S) == LOST_AT:
            old, self.ecu = self.ecu, OdomEcu(self.hal, firmware_params(KOBUKI, "exact"))
            if self.kept:
                self.ecu.params, self.ecu.profile_crc = old.params, old.profile_crc
                self.ecu.odometry.reconfigure(old.odometry._consts)
        super().period(late=late)


def _crcs(board: _Watched) -> tuple[int, set[int], set[int]]:
    """cantools: the PROFILE_CRC before the config, those between its APPLY and the reset,
    those after the reset."""
    applied = board.apply_periods[0]
    return ([crc for k, crc in board.profile_crcs if k < 100][-1],
            {crc for k, crc in board.profile_crcs if applied < k < LOST_AT},
            {crc for k, crc in board.profile_crcs if k > LOST_AT})


def test_a_config_is_lost_with_a_reboot_and_the_judges_say_so() -> None:
    bridge, board = _config_drive("test-bridge-config-lost", _LostBoard, kept=False)
    assert [(r["id"], r["result"]) for r in board.results] == [("c1", "acked")]
    built, configured, rebooted = _crcs(board)
    assert configured
    assert built not in configured  # cantools: the config ran ...
    assert rebooted == {built}  # ... and the build's robot after the reset
    _assert_pose(board, LOST_AT, None)  # 0.23 m from its reset on
    assert _wrongs(bridge, board) == (0, 0)  # PASS, both judges
    lost = ("config lost with the reboot, the build's robot again: 2578 counts/rev, wheel radii "
            "0.035/0.035 m, wheelbase 0.23 m, exact: reference restarted")
    assert _events(bridge, "config")[-1] == lost
    assert [e["detail"] for e in board.monitor.events if e["kind"] == "config"][-1] == lost
    for tracker in (bridge.telemetry.tracker, board.monitor.tracker):
        assert tracker.geometry == Geometry.of(KOBUKI)
    section = bridge.telemetry.profile.section
    assert section is not None
    assert section["verdict"] == "OK", section
    assert board.monitor.health(board.t_s)["state"] == "OK"


def test_a_firmware_that_keeps_its_config_across_a_reboot_fails() -> None:
    bridge, board = _config_drive("test-bridge-config-lost-kept", _LostBoard, kept=True)
    built, configured, rebooted = _crcs(board)
    assert rebooted == configured != {built}  # cantools: it still runs the config
    _assert_pose(board, LOST_AT, LOST_AT)  # 0.25 m from its reset on
    bridge_wrongs, monitor_wrongs = _wrongs(bridge, board)
    assert bridge_wrongs >= 1  # FAIL, both judges
    assert monitor_wrongs >= 1


def test_a_config_taken_in_the_first_tick_after_a_reboot_is_kept() -> None:
    """The firmware ACKs the frames it drains before it sends its boot summary, in the same
    tick: another tool's config delivered in the new firmware's first tick is ACKed (APPLY
    included) before the judges are told of the reboot. They must not take it for a config of
    the old life, lost with the reboot (they did: POSE WRONG on a correct firmware)."""
    with bridged_robot("test-bridge-config-first-tick") as (bridge, listener):
        board = _Watched(bridge, listener)
        for k in range(PERIODS):
            if k == LOST_AT:
                board.ecu = OdomEcu(board.hal, firmware_params(KOBUKI, "exact"))
                board.other_tool(_config_frames(WIDER))
            board.period()
    assert [s["RESULT"] for _, s in board.acks] == [0] * 7  # cantools: all ACKed
    assert board.apply_periods == [LOST_AT]
    _assert_pose(board, LOST_AT, LOST_AT + 1)  # primed on that frame, 0.25 m from the next
    assert _wrongs(bridge, board) == (0, 0)
    for tracker in (bridge.telemetry.tracker, board.monitor.tracker):
        assert tracker.geometry.wheelbase_m == 0.25
