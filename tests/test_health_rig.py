"""Fault scenarios in the lockstep rig: the firmware and the live judge never show OK while the
pose is wrong.

Each scenario runs the whole rig (``tests.fault_rig.FaultRig``) with the live judge
(``host.judge.monitor.BusMonitor``) fed every host frame at its bus time, and checks:

* the firmware's states as ODOM_STATUS reports them (decoded with cantools);
* the judge's verdict (``health``) over time;
* the firmware's final pose against a float64 arc integration of the robot's own encoder counts,
  written here (not ``host.judge.reference``).

``figures()`` prints the closing-note figures: ``python -m tests.test_health_rig``.
"""

from __future__ import annotations

import itertools
import math
import random
from dataclasses import dataclass, field
from typing import Any

import can
import pytest

from odocan.firmware import frames as fr
from odocan.firmware.errors import ErrorFlag, ErrorMask
from odocan.firmware.hal import MAILBOX_SLOTS
from odocan.host.judge.monitor import BusMonitor
from odocan.sim.board import TICK_S, TX_LATENCY_S, FirmwareBoard
from odocan.sim.clock import LockstepClock
from odocan.sim.contract import database
from odocan.sim.robot import load
from odocan.sim.scenarios import get_scenario
from tests import host_frames as hf
from tests.dbc_typed import decode
from tests.fault_rig import FaultRig, open_virtual, robot_params, unique_channel

DB = database()
STATUS = DB.get_message_by_name("ODOM_STATUS")
FIRMWARE_IDS = {0x200, 0x201, 0x202, 0x281, 0x302, 0x380}


@dataclass
class Watch:
    """The host's side of a run: the judge, the firmware's summaries, the judge's verdicts, and
    the robot's own counts per tick (for the independent reference)."""

    rig: FaultRig
    monitor: BusMonitor = field(init=False)
    summaries: list[tuple[float, str, str]] = field(default_factory=list)  # t, STATE, REASON
    verdicts: list[tuple[float, str]] = field(default_factory=list)  # t, health state
    counts: list[tuple[int, int]] = field(default_factory=list)
    last_firmware_s: float = -1.0

    def __post_init__(self) -> None:
        self.monitor = BusMonitor(self.rig.profile, "exact")
        self.rig.observers.append(self)

    def __call__(self, tick: int, frames: list[can.Message]) -> None:
        self.counts.append(self.rig.vehicle.encoder_counts())
        for msg in frames:
            self.monitor.feed(msg, now_s=msg.timestamp)
            if msg.arbitration_id in FIRMWARE_IDS:
                self.last_firmware_s = msg.timestamp
            if msg.arbitration_id == STATUS.frame_id and msg.data[1] >> 4 == 0:
                s = decode(DB, STATUS.frame_id, msg.data)
                self.summaries.append((msg.timestamp, str(s["STATE"]), str(s["REASON"])))
        now_s = tick * TICK_S + TX_LATENCY_S
        self.verdicts.append((now_s, self.monitor.health(now_s)["state"]))

    def states(self) -> list[tuple[str, str]]:
        """The firmware's (STATE, REASON) as reported, consecutive repeats merged."""
        merged: list[tuple[str, str]] = []
        for _, state, reason in self.summaries:
            if not merged or merged[-1] != (state, reason):
                merged.append((state, reason))
        return merged

    def pose_error_m(self) -> float:
        """|on-board - independent reference| now, m (the firmware has taken this tick's frame)."""
        odo = self.rig.ecu.odometry
        x, y = reference_xy(self.counts, self.rig)
        return math.hypot(odo.x_q40_m / 2**40 - x, odo.y_q40_m / 2**40 - y)


def reference_xy(counts: list[tuple[int, int]], rig: FaultRig) -> tuple[float, float]:
    """Float64 dead reckoning over the robot's counts, each step the arc about its ICC."""
    p = rig.profile
    m_left = 2 * math.pi * p.wheel_radius_left_m / p.counts_per_rev
    m_right = 2 * math.pi * p.wheel_radius_right_m / p.counts_per_rev
    half = 1 << (p.counter_bits - 1)
    x = y = heading = 0.0
    for (l0, r0), (l1, r1) in itertools.pairwise(counts):
        ds_left = ((l1 - l0 + half) % (2 * half) - half) * m_left
        ds_right = ((r1 - r0 + half) % (2 * half) - half) * m_right
        ds, dtheta = (ds_left + ds_right) / 2, (ds_right - ds_left) / p.wheelbase_m
        if abs(dtheta) < 1e-12:
            x, y = x + ds * math.cos(heading), y + ds * math.sin(heading)
        else:
            radius = ds / dtheta
            x += radius * (math.sin(heading + dtheta) - math.sin(heading))
            y -= radius * (math.cos(heading + dtheta) - math.cos(heading))
        heading += dtheta
    return x, y


def circle_rig() -> FaultRig:
    """pmir on the ``circle`` scenario: constant curvature, so one long step is an exact arc."""
    return FaultRig(scenario=get_scenario("circle", load("pmir"), duration_s=60.0))


def verdicts_between(watch: Watch, t0: float, t1: float) -> set[str]:
    return {v for t, v in watch.verdicts if t0 <= t < t1}


# --- the scenarios ---------------------------------------------------------------------------


def run_stall(
    halt_ticks: int = 200, set_pose_tick: int | None = None
) -> tuple[Watch, dict[str, Any]]:
    """The MCU halted ``halt_ticks`` ticks from 5 s (a SIGSTOP), then 3 s more; at
    ``set_pose_tick`` (if any) a host tool accepts the on-board pose (ODOM_SET_POSE APPLY), and
    the run goes on 1 s past it. The figures are taken before the set-pose."""
    with circle_rig() as rig:
        watch = Watch(rig)
        tool = open_virtual(rig.channel)
        start = 500
        rig.halted = lambda k: start <= k < start + halt_ticks

        def host(k: int) -> None:
            if k == set_pose_tick:
                data = hf.pack_odom_set_pose(0, fr.SetPoseField.APPLY, 0, ErrorMask())
                tool.send(can.Message(arbitration_id=fr.ODOM_SET_POSE_ID, data=data,
                                      is_extended_id=False, timestamp=k * TICK_S))

        rig.before_board.append(host)
        try:
            end = start + halt_ticks + 300
            rig.run((end if set_pose_tick is None else set_pose_tick) * TICK_S)
            figures = {
                "states": watch.states(),
                "pose_error_m": watch.pose_error_m(),
                "overrun": rig.board.frames_overrun,
                "periods_lost": rig.ecu.periods_lost,
            }
            if set_pose_tick is not None:
                rig.run(1.0)
                figures["after_set_pose"] = (watch.states()[-1], watch.verdicts[-1][1])
        finally:
            tool.shutdown()
        return watch, figures


def test_a_stalled_firmware_is_stale_then_degraded_until_a_set_pose_with_its_pose_right() -> None:
    # The 2 s stall is one merged step whose path the firmware cannot know (its worst case is
    # metres): DEGRADED POSE_UNCERTAIN, latched, never OK by itself; OK again after the host
    # sets the pose (at 9 s, 2 s after the MCU runs again).
    watch, figures = run_stall(set_pose_tick=900)
    assert figures["states"] == [
        ("OK", "NONE"), ("DEGRADED", "TIME_LOST"), ("DEGRADED", "POSE_UNCERTAIN")
    ]
    assert figures["periods_lost"] == 200  # 201 periods between two ticks
    assert figures["overrun"] > 0  # the backlog beyond the controller's FIFO was lost
    assert figures["pose_error_m"] < 1e-4  # the arc across the stall: within one LSB of X/Y
    assert verdicts_between(watch, 5.25, 7.0) == {"STALE"}
    assert "OK" not in verdicts_between(watch, 5.25, 9.0)  # latched until the set-pose
    assert figures["after_set_pose"] == (("OK", "NONE"), "OK")  # the host took the pose


def run_silence() -> tuple[Watch, float]:
    """The firmware dies at 5 s (kill -9); returns the time from its last frame to STALE."""
    with circle_rig() as rig:
        watch = Watch(rig)
        rig.halted = lambda k: k >= 500
        rig.run(7.0)
        last = watch.last_firmware_s
        stale_at = min(t for t, v in watch.verdicts if v == "STALE")
        return watch, stale_at - last


def test_a_silent_firmware_is_stale_after_ten_cycles() -> None:
    watch, to_stale_s = run_silence()
    assert 0.2 < to_stale_s <= 0.2 + TICK_S  # 10 x ODOM_POSE_X's 20 ms, seen at the next tick
    assert watch.monitor.status["state"] == "OK"  # what it last said: the verdict says STALE
    assert {v for t, v in watch.verdicts if t > watch.last_firmware_s + 0.21} == {"STALE"}


def run_reboot() -> tuple[Watch, dict[str, Any]]:
    """The firmware restarts at 5 s (a new ECU on the same board and bus)."""
    with circle_rig() as rig:
        watch = Watch(rig)

        def reboot(k: int) -> None:
            if k == 500:
                rig.board = FirmwareBoard(rig.fw_bus, rig.params, rig.clock)

        rig.before_board.append(reboot)
        rig.run(8.0)
        health = watch.monitor.health(8.0)
        figures = {
            "events": [e["kind"] for e in health["events"]],
            "verdict": health["state"],
            "reference_starts": watch.monitor.tracker.reference_starts,
            "vs_reference_m": watch.monitor.tracker.vs_reference.latest["dpos_m"],
            "lost": {
                n: watch.monitor.e2e.counts()[n]["lost"] for n in ("ODOM_POSE_X", "ODOM_STATUS")
            },
        }
        return watch, figures


def test_a_reboot_is_an_event_and_restarts_the_reference() -> None:
    _, figures = run_reboot()
    assert figures["events"] == ["reboot"]
    assert figures["reference_starts"] == 2
    assert figures["vs_reference_m"] < 2e-4
    assert figures["lost"] == {"ODOM_POSE_X": 0, "ODOM_STATUS": 0}  # not "lost 10"
    assert figures["verdict"] == "OK"


def run_counter_reset() -> tuple[Watch, dict[str, Any]]:
    """The motor controller reboots at 5 s: its counters and E2E counter restart from 0; at 8 s
    a host tool accepts the on-board pose (ODOM_SET_POSE APPLY), at 9 s the run ends."""
    with circle_rig() as rig:
        watch = Watch(rig)
        tool = open_virtual(rig.channel)

        def host(k: int) -> None:
            if k == 499:
                rig.sim.motor_controller.restart()
            if k == 800:
                data = hf.pack_odom_set_pose(0, fr.SetPoseField.APPLY, 0, ErrorMask())
                tool.send(
                    can.Message(
                        arbitration_id=fr.ODOM_SET_POSE_ID,
                        data=data,
                        is_extended_id=False,
                        timestamp=k * TICK_S,
                    )
                )

        rig.before_board.append(host)
        try:
            rig.run(8.0)
            figures = {
                "states": watch.states(),
                "verdict": watch.verdicts[-1][1],
                "pose_error_m": watch.pose_error_m(),
                "implausible": rig.ecu.frames_implausible,
            }
            rig.run(1.0)
        finally:
            tool.shutdown()
        figures["after_set_pose"] = (watch.states()[-1], watch.verdicts[-1][1])
        figures["events"] = [e["kind"] for e in watch.monitor.events]
        return watch, figures


def test_a_counter_reset_is_not_integrated_and_never_called_ok() -> None:
    watch, figures = run_counter_reset()
    assert figures["states"][0] == ("OK", "NONE")
    assert figures["states"][-1] == ("DEGRADED", "COUNTER_RESET")
    assert figures["verdict"] == "DEGRADED"
    assert "OK" not in verdicts_between(watch, 5.2, 8.0)
    assert figures["pose_error_m"] < 0.1  # the motion while the frames were refused, not 2 m
    assert figures["after_set_pose"] == (("OK", "NONE"), "OK")  # the host took the pose
    assert figures["events"] == ["counter_restart", "set_pose"]  # the restart named, as analyze


def run_duplicate() -> tuple[Watch, dict[str, Any]]:
    """A second firmware on the same node IDs from 3 s on."""
    with circle_rig() as rig:
        watch = Watch(rig)
        second: list[FirmwareBoard] = []

        def twin(k: int) -> None:
            if k == 300:  # powered up now: its controller hears the bus from now on
                second.append(FirmwareBoard(open_virtual(rig.channel), rig.params, rig.clock))
            if second:
                second[0].run_tick()

        rig.before_board.append(twin)
        try:
            rig.run(6.0)
        finally:
            for board in second:
                board.bus.shutdown()
        health = watch.monitor.health(6.0)
        figures = {
            "events": [e["kind"] for e in health["events"]],
            "verdict": health["state"],
            "states": watch.states(),
        }
        return watch, figures


def test_two_firmwares_on_one_node_id_are_a_conflict() -> None:
    watch, figures = run_duplicate()
    assert figures["events"] == ["reboot", "two sources"]  # the newcomer's UPTIME went back first
    assert figures["verdict"] == "CONFLICT"
    assert "OK" not in verdicts_between(watch, 3.5, 6.0)


def run_forgery(seconds: float = 4.0, per_tick: int = 80) -> tuple[Watch, dict[str, Any]]:
    """Random payloads on the encoder ID at ``per_tick`` x 100 frames/s from 2 s on."""
    with circle_rig() as rig:
        watch = Watch(rig)
        attacker = open_virtual(rig.channel)
        rng = random.Random(7)

        def forge(k: int) -> None:
            if k >= 200:
                for _ in range(per_tick):
                    attacker.send(
                        can.Message(
                            arbitration_id=0x100,
                            is_extended_id=False,
                            data=rng.randbytes(8),
                            timestamp=k * TICK_S,
                        )
                    )

        rig.before_board.append(forge)
        try:
            rig.run(2.0 + seconds)
        finally:
            attacker.shutdown()
        figures = {
            "states": watch.states(),
            "pose_error_m": watch.pose_error_m(),
            "implausible": rig.ecu.frames_implausible,
            "overflows": rig.ecu.mailbox.overflows,
        }
        return watch, figures


def test_forged_encoder_frames_never_move_the_pose_and_are_never_ok() -> None:
    watch, figures = run_forgery()
    flood = [state for t, state, _ in watch.summaries if t > 2.05]
    assert flood
    assert "OK" not in flood
    assert figures["pose_error_m"] < 1e-4
    assert "OK" not in verdicts_between(watch, 2.05, 6.0)


def figures() -> None:
    """The closing-note figures."""
    for name, run in (
        ("stall 2 s", lambda: run_stall(set_pose_tick=900)),
        ("reboot", run_reboot),
        ("counter reset", run_counter_reset),
        ("duplicate", run_duplicate),
        ("forgery 8000/s", run_forgery),
        ("forgery 800/s, 20 s", lambda: run_forgery(20.0, 8)),
    ):
        watch, result = run()
        print(f"{name}: {result}; final verdict {watch.verdicts[-1][1]}")
    _, to_stale = run_silence()
    print(f"silence -> STALE: {to_stale:.3f} s")


@pytest.mark.parametrize(
    ("late_s", "overrun", "filtered", "overflows"), [(0.05, 0, MAILBOX_SLOTS, 8), (2.0, 37, 3, 1)]
)
def test_a_halted_board_keeps_only_its_controller_fifo(
    late_s: float, overrun: int, filtered: int, overflows: int
) -> None:
    """40 frames wait. A tick 50 ms late delivers them all (the ISR would have run: the 32-slot
    mailbox overflows by 8); after a 2 s halt only the receive FIFO's 3 oldest frames reach the
    firmware, the rest are overrun and the overrun interrupt counts once."""
    channel = unique_channel()
    clock = LockstepClock()
    sender, board_bus = open_virtual(channel), open_virtual(channel)
    try:
        board = FirmwareBoard(board_bus, robot_params(load("pmir"), "exact"), clock)
        board.run_tick()
        clock.advance_to(late_s)
        for n in range(40):
            sender.send(
                can.Message(arbitration_id=0x555, data=bytes([n] * 8), is_extended_id=False)
            )
        board.run_tick()
        assert board.frames_overrun == overrun
        assert board.ecu.frames_filtered == filtered
        assert board.ecu.mailbox.overflows == overflows
        assert board.ecu.errors.has(ErrorFlag.TIME_LOST) == (overrun > 0)
    finally:
        sender.shutdown()
        board_bus.shutdown()


def test_forged_frames_that_pass_e2e_are_refused_as_implausible() -> None:
    """800 frames/s: the mailbox holds them, about 1/256 pass the CRC and some the sequence
    check; each is refused by the plausibility bound (DEGRADED) and the pose never moves."""
    _, figures = run_forgery(seconds=20.0, per_tick=8)
    assert figures["overflows"] == 0
    assert figures["implausible"] >= 1
    assert ("DEGRADED", "IMPLAUSIBLE_STEP") in figures["states"]
    assert figures["pose_error_m"] < 1e-4


def test_multiplexed_messages_have_per_page_rates_and_jitter() -> None:
    """On a perfectly regular bus every page of ODOM_STATUS and SIM_TRUTH is regular: no period
    jitter (the pages sent together are not one message's period)."""
    with circle_rig() as rig:
        watch = Watch(rig)
        rig.run(4.0)
        messages = watch.monitor.snapshot(4.0)["messages"]
    status, truth = messages["ODOM_STATUS"], messages["SIM_TRUTH"]
    assert status["jitter_ms"] is None
    assert truth["jitter_ms"] is None
    assert status["pages"]["SUMMARY"]["rate_hz"] == pytest.approx(10.0)
    for page in ("FRAME_TOTALS", "E2E_WHEEL_ENCODERS", "E2E_NAV_GOAL", "PROFILE"):
        assert status["pages"][page]["rate_hz"] == pytest.approx(10.0 / 6)  # six rotate
    for part in ("X", "Y", "HEADING"):
        assert truth["pages"][part]["rate_hz"] == pytest.approx(10.0)
    for pages in (status["pages"], truth["pages"]):
        assert max(p["jitter_ms"] for p in pages.values()) < 1e-6
    assert messages["WHEEL_ENCODERS"]["jitter_ms"] < 1e-6
    assert "pages" not in messages["ODOM_POSE_X"]


if __name__ == "__main__":
    figures()


def test_frames_before_the_board_joins_the_bus_never_reach_the_firmware() -> None:
    """``odocan firmware`` opens its bus before the firmware's first tick: 79 frames came in
    0.7 s on a loaded machine, and the first tick gave them all to the ISR (the mailbox dropped
    35, the firmware merged their steps: ``tests/test_trial38.py``). A controller receives
    nothing before it leaves initialization mode: joined, the board takes only what comes after."""
    channel = unique_channel()
    sender, board_bus = open_virtual(channel), open_virtual(channel)
    try:
        board = FirmwareBoard(board_bus, robot_params(load("pmir"), "exact"), LockstepClock())
        for n in range(40):
            sender.send(can.Message(arbitration_id=0x555, data=bytes([n] * 8),
                                    is_extended_id=False))
        assert board.join_bus() == 40
        sender.send(can.Message(arbitration_id=0x555, data=bytes(8), is_extended_id=False))
        board.run_tick()
        assert board.ecu.frames_filtered == 1
        assert board.ecu.mailbox.overflows == 0
    finally:
        sender.shutdown()
        board_bus.shutdown()
