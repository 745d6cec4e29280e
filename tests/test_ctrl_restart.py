"""A restart of the motor controller is never integrated as motion (issue #11, item 5).

The controller (node MOTOR_CTRL) says its age in WHEEL_ENCODERS' CTRL_UPTIME (1 + whole seconds
since its power-up, saturating at 15; 0: an old controller that does not say). When it restarts
after a silence long enough, the jump of its counters (from 0) fits the firmware's time-widened
speed bound, and no rule on the counts alone tells it from motion; CTRL_UPTIME going down does.
The firmware re-primes on that frame (DEGRADED COUNTER_RESET until a set-pose), in Python and in
C bit for bit.
"""

from __future__ import annotations

import dataclasses
import signal
import subprocess
from pathlib import Path
from typing import Any

import can
import pytest

from odocan.firmware import frames as fr
from odocan.firmware import uncertainty
from odocan.firmware.encoders import EncoderInput
from odocan.firmware.fixmath import U32_MAX
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import HEADING_LSB_RAD, POSITION_LSB_M, analyze
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.stream_analysis import analyze_file
from odocan.host.judge.unseenrestart import restart_detail
from odocan.sim.board import TICK_S
from odocan.sim.contract import database
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.robot import RobotProfile, load
from tests.dbc_typed import decode
from tests.independent_checker import Robot, check
from tests.synth_log import Synth, synthesize, wandering_drive
from tests.test_realtime import START_TIMEOUT_S, _listen, _start, _stop, udp_bus

__all__ = ["udp_bus"]  # the fixture of tests/test_realtime.py (a channel of this test's own)

DB = database()
STATUS = DB.get_message_by_name("ODOM_STATUS")
ENCODERS = DB.get_message_by_name("WHEEL_ENCODERS")
SILENT_FROM = 500  # tick (5 s): the controller falls silent
SILENT_TICKS = 200  # 2 s; it restarts as it speaks again
END_TICKS = SILENT_FROM + SILENT_TICKS + 300


def silenced_log(path: Path, firmware: str, silent: tuple[int, int], restart_tick: int,
                 end_ticks: int) -> Path:
    """pmir on a circle; the motor controller silent for ``silent`` (first tick, ticks) and
    restarted (counters, COUNTER and CTRL_UPTIME from 0) at ``restart_tick``; the run ends at
    tick ``end_ticks``. The candump log of the whole run."""
    first, ticks = silent
    config = RigConfig(robot=load("pmir"), scenario="circle", firmware=firmware, duration_s=60.0)
    with LockstepRig(config, [can.Logger(path)]) as rig:
        send = rig.sim.tick

        def tick(k: int) -> None:
            if k == restart_tick:
                rig.sim.motor_controller.restart()
            if not first <= k < first + ticks:
                send(k)

        rig.sim.tick = tick  # type: ignore[method-assign]
        rig.run(end_ticks * TICK_S)
    return path


def restart_log(path: Path, firmware: str) -> Path:
    """pmir on a circle; the motor controller silent 2 s from 5 s, then restarted (counters,
    COUNTER and CTRL_UPTIME from 0); 3 s more. The candump log of the whole run."""
    return silenced_log(path, firmware, (SILENT_FROM, SILENT_TICKS), SILENT_FROM + SILENT_TICKS,
                        END_TICKS)


def summaries(path: Path) -> list[tuple[float, str, str]]:
    """(bus time s, STATE, REASON) of every ODOM_STATUS summary, decoded by cantools."""
    out = []
    for msg in can.LogReader(path):
        if msg.arbitration_id == STATUS.frame_id and msg.data[1] >> 4 == 0:
            s = decode(DB, STATUS.frame_id, msg.data)
            out.append((msg.timestamp, str(s["STATE"]), str(s["REASON"])))
    return out


def uptimes(path: Path) -> list[int]:
    """CTRL_UPTIME of every WHEEL_ENCODERS frame, decoded by cantools."""
    return [int(str(decode(DB, ENCODERS.frame_id, m.data)["CTRL_UPTIME"]))
            for m in can.LogReader(path) if m.arbitration_id == ENCODERS.frame_id]


def test_python_and_c_firmwares_reprime_on_a_controller_restart_bit_for_bit(
    tmp_path: Path,
) -> None:
    python = restart_log(tmp_path / "python.log", "python")
    c = restart_log(tmp_path / "c.log", "c")
    assert python.read_bytes() == c.read_bytes()
    heard = uptimes(python)
    assert heard[SILENT_FROM - 1] == 5
    assert heard[SILENT_FROM] == 1
    restart_s = (SILENT_FROM + SILENT_TICKS) * TICK_S
    after = [(state, reason) for t, state, reason in summaries(python) if t > restart_s + 0.05]
    assert after
    assert set(after) == {("DEGRADED", "COUNTER_RESET")}


# --- the judges, on hand-made logs ------------------------------------------------------------

STEPS = 1200  # 12 s of driving
RESTART = 600  # the encoder frame the restarted controller speaks again on (CTRL_UPTIME 6 -> 1)
JUMP = (30, -12)  # its counters' jump (counts): within the plausibility bound of one period


def profile_of(robot: str) -> RobotProfile:
    """The shipped profile, bounded at 4 m/s: the synthesized restart keeps the counters near
    their old values (~28 000 counts after 6 s), which a controller 1 s old can hold only at
    4 m/s (47 000 counts a second on kobuki); at kobuki's own 0.7 m/s (8 400) the firmware
    rightly refuses the frame instead of re-priming (the rig's real restart counts from 0)."""
    return dataclasses.replace(load(robot), max_wheel_speed_m_s=4.0)


def restart_drive(robot: str, *, ctrl_uptime: bool = True, integrates: bool = False) -> Synth:
    """A wandering drive whose motor controller restarts at ``RESTART`` (``tests.synth_log``):
    ``ctrl_uptime`` False, an old controller (CTRL_UPTIME 0); ``integrates``: a firmware that
    takes the jump as motion."""
    profile = profile_of(robot)
    d_left, d_right = wandering_drive(profile, STEPS, 0.004, seed=7)
    return synthesize(profile, "exact", d_left, d_right, ctrl_restarts={RESTART: JUMP},
                      ctrl_uptime=ctrl_uptime, integrates_restarts=integrates)


def judged(path: Path, robot: str) -> dict[str, Any]:
    """The independent checker's verdict, ``analyze``'s (whole and streamed, with their
    counter-restart events) and the live monitor's (its worst error vs its reference within
    one LSB, and its verdict at the end)."""
    profile = profile_of(robot)
    p = profile.firmware_params()
    checker = Robot(p["counts_per_rev"], p["wheel_radius_left_nm"], p["wheel_radius_right_nm"],
                    p["wheelbase_nm"], p["counter_bits"])
    whole = analyze(read_log(path), profile).report
    streamed = analyze_file(path, profile, chunk_frames=256)
    monitor = BusMonitor(profile)
    last_s = 0.0
    for msg in can.LogReader(path):
        monitor.feed(msg, now_s=msg.timestamp)
        last_s = msg.timestamp
    error = monitor.tracker.vs_reference
    return {
        "independent": check(path, checker, "exact", lambda _t: (0.0, 0.0, 0.0)).passed,
        "whole": whole["passed"], "streamed": streamed["passed"],
        "live": error.max_dpos_m <= POSITION_LSB_M and error.max_dheading_rad <= HEADING_LSB_RAD,
        "live_verdict": monitor.health(last_s)["state"],
        "events": [[(e["encoder_frame"], e["detail"]) for e in r["events"]
                    if e["kind"] == "counter_restart"] for r in (whole, streamed)],
        "live_events": [(e["t_s"], e["detail"]) for e in monitor.health(last_s)["events"]
                        if e["kind"] == "counter_restart"],
        "restart_t_s": [e["t_s"] for e in whole["events"] if e["kind"] == "counter_restart"],
    }


@pytest.mark.parametrize("robot", ["kobuki", "pmir"])
def test_a_firmware_that_reprimed_on_the_restart_passes_every_judge(
    tmp_path: Path, robot: str
) -> None:
    path = restart_drive(robot).write(tmp_path / "reprimed.log")
    heard = uptimes(path)
    assert heard[RESTART - 1] == 6  # the age went back: 1 + 5 whole seconds ...
    assert heard[RESTART] == 1  # ... to 1
    verdict = judged(path, robot)
    assert verdict["independent"]
    assert verdict["whole"]
    assert verdict["streamed"]
    assert verdict["live"]
    assert verdict["live_verdict"] == "OK"
    for events in verdict["events"]:  # named, whole and streamed alike
        assert len(events) == 1
        frame, detail = events[0]
        assert frame == RESTART
        assert "CTRL_UPTIME went back" in detail
    live = verdict["live_events"]  # the monitor names it too, at the same frame's time
    assert [t_s for t_s, _ in live] == verdict["restart_t_s"]
    assert "the motor controller restarted (CTRL_UPTIME went back)" in live[0][1]


@pytest.mark.parametrize("robot", ["kobuki", "pmir"])
def test_a_firmware_that_integrated_the_restart_fails_every_judge(
    tmp_path: Path, robot: str
) -> None:
    path = restart_drive(robot, integrates=True).write(tmp_path / "integrated.log")
    verdict = judged(path, robot)
    assert not verdict["independent"]
    assert not verdict["whole"]
    assert not verdict["streamed"]
    assert not verdict["live"]
    assert verdict["live_verdict"] == "POSE WRONG"


def test_an_old_controller_is_judged_by_the_counts_alone(tmp_path: Path) -> None:
    """CTRL_UPTIME always 0: the same jump cannot be told from motion; the firmware that
    integrates it (what it must do without the age) passes, as before the signal."""
    path = restart_drive("kobuki", ctrl_uptime=False, integrates=True).write(tmp_path / "old.log")
    assert set(uptimes(path)) == {0}
    verdict = judged(path, "kobuki")
    assert verdict["independent"]
    assert verdict["whole"]
    assert verdict["streamed"]
    assert verdict["live"]
    assert verdict["events"] == [[], []]


# --- as processes: ``odocan sim`` killed and started again -------------------------------------


def test_a_sim_process_killed_and_restarted_is_a_counter_reset_never_ok(
    udp_bus: tuple[list[str], can.BusABC],
) -> None:
    """``odocan firmware`` and ``odocan sim`` on a loopback udp_multicast channel of their own;
    the sim is killed (SIGKILL) after 1.6 s of driving and started again: its counters, COUNTER
    and CTRL_UPTIME from 0. The firmware's summaries after it say DEGRADED COUNTER_RESET, never
    OK, and the monitor's model of the frames heard never says OK or POSE WRONG after it."""
    bus_argv, listener = udp_bus
    firmware = _start(["firmware", *bus_argv])
    sims: list[subprocess.Popen[str]] = []
    try:
        # the sim starts once the firmware is heard (its status, before any encoder frame): a
        # firmware still starting (a loaded machine) joined the drive 16 or more encoder frames
        # late, where ENC_COUNTER (4 bits) no longer names the frame its pose is on
        up = _listen(listener, lambda c: bool(c.of(fr.ODOM_STATUS_ID)), START_TIMEOUT_S + 40)
        assert up.of(fr.ODOM_STATUS_ID), "the firmware was not heard"
        sims.append(_start(["sim", "--scenario", "circle", "--duration", "30", *bus_argv]))
        first = _listen(listener, lambda c: len(c.of(fr.WHEEL_ENCODERS_ID)) >= 160,
                        START_TIMEOUT_S + 5)
        sims[0].kill()
        sims.append(_start(["sim", "--scenario", "circle", "--duration", "30", *bus_argv]))
        again = _listen(listener, lambda c: len(c.of(fr.WHEEL_ENCODERS_ID)) >= 200,
                        START_TIMEOUT_S + 5)
    finally:
        for sim in sims:
            _stop(sim, signal.SIGTERM)
        _stop(firmware, signal.SIGTERM)
    assert len(first.of(fr.WHEEL_ENCODERS_ID)) >= 160
    assert len(again.of(fr.WHEEL_ENCODERS_ID)) >= 200
    back_s = again.of(fr.WHEEL_ENCODERS_ID)[0].timestamp  # the restarted sim's first frame
    monitor = BusMonitor(load("pmir"))
    verdicts: list[tuple[float, str]] = []
    status: list[tuple[float, str, str]] = []
    for msg in [*up.frames, *first.frames, *again.frames]:
        monitor.feed(msg, now_s=msg.timestamp)
        if msg.timestamp > back_s:
            verdicts.append((msg.timestamp, monitor.health(msg.timestamp)["state"]))
            if msg.arbitration_id == STATUS.frame_id and msg.data[1] >> 4 == 0:
                s = decode(DB, STATUS.frame_id, msg.data)
                status.append((msg.timestamp, str(s["STATE"]), str(s["REASON"])))
    reset_s = next(t for t, state, reason in status if reason == "COUNTER_RESET")  # noticed
    assert {(st, r) for t, st, r in status if t >= reset_s} == {("DEGRADED", "COUNTER_RESET")}
    assert "OK" not in {v for t, v in verdicts if t >= reset_s}
    assert "POSE WRONG" not in {v for _, v in verdicts}
    told = [e for e in monitor.health(again.frames[-1].timestamp)["events"]
            if e["kind"] == "counter_restart"]  # the monitor names the restart
    assert told
    # the frames heard may go dark across the kill (no frame for DARK_CYCLES: the loaded
    # machine starves the firmware's process): then it is a restart after frames the host
    # never heard (``host.judge.livedark``), as analyze would judge that capture
    assert told[0]["detail"] in {restart_detail(True), restart_detail(True, unseen=True)}
    assert told[0]["t_s"] >= back_s


@pytest.mark.parametrize(("robot", "scenario"), [("pmir", "circle"), ("kobuki", "random")])
def test_a_restart_without_a_silence_passes_on_a_correct_firmware(
    tmp_path: Path, robot: str, scenario: str
) -> None:
    """The controller restarts between two periods: the firmware re-primes on the first frame
    it takes after it (E2E refuses the restarted COUNTERs a while) and its twist there holds the
    last value; analyze, whole and streamed (the twist included), and the monitor pass it."""
    path = tmp_path / "restart.log"
    config = RigConfig(robot=load(robot), scenario=scenario, duration_s=60.0, seed=2)
    with LockstepRig(config, [can.Logger(path)]) as rig:
        send = rig.sim.tick

        def tick(k: int) -> None:
            if k == 300:
                rig.sim.motor_controller.restart()
            send(k)

        rig.sim.tick = tick  # type: ignore[method-assign]
        rig.run(8.0)
    assert ("DEGRADED", "COUNTER_RESET") in {(s, r) for _, s, r in summaries(path)}
    whole = analyze(read_log(path), load(robot)).report
    assert whole["passed"], (whole["onboard_vs_reference"], whole["onboard_twist_vs_reference"])
    assert [e["kind"] for e in whole["events"]] == ["counter_restart"]
    assert analyze_file(path, load(robot), chunk_frames=300)["passed"]
    monitor = BusMonitor(load(robot))
    for msg in can.LogReader(path):
        monitor.feed(msg, now_s=msg.timestamp)
    assert monitor.tracker.counter_restarts == 1
    assert monitor.tracker.vs_reference.max_dpos_m <= POSITION_LSB_M


# --- a restart inside a silence, the controller back older than it was before it ----------------

AGED_RESTART = 900  # tick (9 s): the controller restarts while silent (500 .. 1500)
AGED_SILENT_TICKS = 1000  # 10 s: it speaks again 6 s after its restart, CTRL_UPTIME 7 > 5


def aged_restart_log(path: Path, firmware: str) -> Path:
    """pmir on a circle; the motor controller silent 10 s from 5 s, restarted 4 s into the
    silence: it speaks again with CTRL_UPTIME 7, above the 5 it said before the silence (the old
    rule, CTRL_UPTIME below the last, cannot tell it) but below the 5 + 9 whole seconds of the
    silence. 3 s more. The candump log of the whole run."""
    return silenced_log(path, firmware, (SILENT_FROM, AGED_SILENT_TICKS), AGED_RESTART,
                        SILENT_FROM + AGED_SILENT_TICKS + 300)


def test_a_controller_back_older_than_before_a_silence_is_a_restart_in_python_and_c(
    tmp_path: Path,
) -> None:
    """The jump to the restarted counters fits the bound widened by 10 s of silence: without
    the rule "aged less than the silence" the firmware integrated it as motion and went back to
    OK; now it re-primes (DEGRADED COUNTER_RESET, never OK), Python and C bit for bit, and every
    judge passes it, naming the restart."""
    python = aged_restart_log(tmp_path / "python.log", "python")
    c = aged_restart_log(tmp_path / "c.log", "c")
    assert python.read_bytes() == c.read_bytes()
    heard = uptimes(python)
    assert heard[SILENT_FROM - 1] == 5
    assert heard[SILENT_FROM] == 7
    back_s = (SILENT_FROM + AGED_SILENT_TICKS) * TICK_S
    after = [(state, reason) for t, state, reason in summaries(python) if t > back_s + 0.05]
    assert after
    assert set(after) == {("DEGRADED", "COUNTER_RESET")}
    profile = load("pmir")
    whole = analyze(read_log(python), profile).report
    assert whole["passed"], whole["onboard_vs_reference"]
    assert [e["kind"] for e in whole["events"]] == ["counter_restart"]
    assert analyze_file(python, profile, chunk_frames=256)["passed"]
    monitor = BusMonitor(profile)
    for msg in can.LogReader(python):
        monitor.feed(msg, now_s=msg.timestamp)
    assert monitor.tracker.vs_reference.max_dpos_m <= POSITION_LSB_M
    told = [e for e in monitor.health(msg.timestamp)["events"] if e["kind"] == "counter_restart"]
    assert [e["t_s"] for e in told] == [e["t_s"] for e in whole["events"]]


def test_a_firmware_that_integrated_the_aged_restart_fails_every_judge(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The same drive on a firmware without the rule (its ``_aged_uptime`` the last CTRL_UPTIME
    alone, as before): it integrates the restart's jump, and analyze (whole and streamed) and
    the monitor fail it."""
    monkeypatch.setattr(EncoderInput, "_aged_uptime", lambda self, prev, counter: prev)
    # and without the ambiguity rule (tests/test_wrap_in_silence.py), which 10 s of silence
    # on pmir reach too: it would re-prime on the jump for its own reason
    monkeypatch.setattr(EncoderInput, "_least_ambiguous_periods", lambda _self: 1 << 20)
    # and without the pose-uncertainty rule (tests/test_pose_uncertainty.py), which says
    # DEGRADED POSE_UNCERTAIN after any 10 s step: as before, it claims OK on the wrong pose
    monkeypatch.setattr(uncertainty, "UNCERTAINTY_TOLERANCE_UM", U32_MAX)
    path = aged_restart_log(tmp_path / "integrated.log", "python")
    after = [(s, r) for t, s, r in summaries(path)
             if t > (SILENT_FROM + AGED_SILENT_TICKS) * TICK_S + 2.0]
    assert ("OK", "NONE") in set(after)  # it recovered: OK with the jump in its pose
    profile = load("pmir")
    assert not analyze(read_log(path), profile).report["passed"]
    assert not analyze_file(path, profile, chunk_frames=256)["passed"]
    monitor = BusMonitor(profile)
    for msg in can.LogReader(path):
        monitor.feed(msg, now_s=msg.timestamp)
    assert monitor.tracker.vs_reference.max_dheading_rad > HEADING_LSB_RAD  # its position is
    # placed again after the gap (bounded), its heading goes on


def test_a_firmware_whose_position_jumps_at_a_restart_inside_a_gap_fails_every_judge(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The controller silent 2 s, restarted as it speaks again: a firmware that re-primes but
    moves its X by 39 mm there (2^-5 m: a wrong re-prime). The judges placed the reference's
    position again after the gap, bounded by the counts across it, which across a restart are
    its jump, not motion: the wrong pose passed every judge (whole, streamed, live; its heading,
    never placed, was right). Across a restart the firmware integrates nothing, so the position
    goes on exactly: 39 mm off FAILs; the correct firmware still passes (the tests above)."""
    reprime = EncoderInput._reprime

    def jumped(self: EncoderInput, counter: int, wire: tuple[int, int],
               counts: tuple[int, int]) -> None:
        reprime(self, counter, wire, counts)
        self._odometry.x_q40_m += 1 << 35  # 2^-5 m

    monkeypatch.setattr(EncoderInput, "_reprime", jumped)
    path = restart_log(tmp_path / "jumped.log", "python")
    profile = load("pmir")
    whole = analyze(read_log(path), profile).report
    assert whole["onboard_vs_reference"]["max_position_error_m"] > 0.03
    assert whole["onboard_vs_reference"]["max_heading_error_rad"] <= HEADING_LSB_RAD
    assert not whole["passed"]
    assert not analyze_file(path, profile, chunk_frames=256)["passed"]
    monitor = BusMonitor(profile)
    for msg in can.LogReader(path):
        monitor.feed(msg, now_s=msg.timestamp)
    assert monitor.tracker.vs_reference.max_dpos_m > 0.03
