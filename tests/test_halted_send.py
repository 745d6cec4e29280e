"""A firmware halted in the middle of a tick sends the rest of it when it resumes: one firmware,
not two (issue #11 item 5, ``host.judge.haltedsend``).

Found (trial38, ``tests/test_trial38.py``): ``odocan firmware`` stopped 2 s by ``kill -STOP``
on a loaded host; the monitor said CONFLICT "two senders of ODOM_STATUS interleave" for the one
resumed firmware. Traced (its ``--log``, and again with the stop sent while the firmware was
runnable): the stop landed between the tick's ODOM_POSE_X and the rest of the tick, whose
ODOM_STATUS summary (UPTIME read before the halt) came 2.1 s late; the next summary was back
on the offset, and the two offsets "interleaved". Here the same sequence, made by hand from a
lockstep drive (``--faults stall=2.91:2``, pmir): the halted tick's frames after its ODOM_POSE_X
moved to just before the firmware's first frame after the halt (as the process log had them).
"""

from __future__ import annotations

from pathlib import Path

import can
import pytest

from odocan.host.judge.haltedsend import sent_after_halt
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.sources import UPTIME_MATCH_S
from odocan.sim.robot import load
from tests.judges_cli import (
    POSE_X,
    cli,
    fails_by_position,
    raise_first_x,
    raise_x_10_mm,
    reported_analyses,
    x_10_mm_off_fails,
)
from tests.log_edit import drop_frames, raise_raw
from tests.test_live_reboot import bridge_of

HALT_S = 2.91  # the stall's start: the tick before it (2.90 s) sends a summary and a page
FIRMWARE_IDS = frozenset({0x200, 0x201, 0x202, 0x281, 0x380})  # pose X/Y, twist, nav, status
STATUS_ID = 0x380


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    log = tmp_path_factory.mktemp("halted") / "d.log"
    done = cli("run", "--scenario", "random", "--seed", "7", "--duration", "8",
               "--faults", f"stall={HALT_S}:2", "--log", str(log))
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    return log


@pytest.fixture(scope="module")
def kobuki_drive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The same on kobuki: its 2 s halt ends in COUNTER_RESET (the step's bound reached)."""
    log = tmp_path_factory.mktemp("halted_kobuki") / "d.log"
    done = cli("run", "--robot", "kobuki", "--scenario", "random", "--seed", "7", "--duration",
               "8", "--faults", f"stall={HALT_S}:2", "--log", str(log))
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    return log


def halted_mid_tick(src: Path, dst: Path, ids: frozenset[int]) -> float:
    """Copy ``src`` to ``dst`` with the frames of ``ids`` of the last firmware tick before the
    halt, but its ODOM_POSE_X, sent at the halt's end (just before the firmware's first frame
    after it, in their order): the bus time they come at, returned."""
    msgs = list(can.LogReader(str(src)))
    t0 = msgs[0].timestamp
    last_s = max(m.timestamp for m in msgs
                 if m.arbitration_id in FIRMWARE_IDS and m.timestamp - t0 < HALT_S)
    tick = [m for m in msgs if m.timestamp == last_s and m.arbitration_id in FIRMWARE_IDS]
    late = [m for m in tick[1:] if m.arbitration_id in ids]
    assert late, tick
    assert tick[0].arbitration_id == 0x200, tick  # its ODOM_POSE_X, sent before the halt
    rest = [m for m in msgs if all(m is not x for x in late)]
    k = next(i for i, m in enumerate(rest)
             if m.arbitration_id in FIRMWARE_IDS and m.timestamp - t0 > HALT_S)
    resume_s = rest[k].timestamp - 1e-3
    assert resume_s - last_s > 2.0  # as long late as the halt
    for i, msg in enumerate(late):
        msg.timestamp = resume_s + i * 1e-5
    with can.Logger(str(dst)) as out:
        for msg in [*rest[:k], *late, *rest[k:]]:
            out.on_message_received(msg)
    return resume_s - t0


def _monitor_states(log: Path, robot: str = "pmir") -> tuple[BusMonitor, set[str]]:
    """The monitor fed ``log``; the states its health said after each ODOM_STATUS frame."""
    monitor, states = BusMonitor(load(robot), "exact"), set()
    for msg in can.LogReader(str(log)):
        monitor.feed(msg, now_s=msg.timestamp)
        if msg.arbitration_id == STATUS_ID:
            states.add(monitor.health(msg.timestamp)["state"])
    return monitor, states


def test_a_summary_sent_after_the_halt_is_one_firmware_for_every_judge(
        drive: Path, tmp_path: Path) -> None:
    """The halted tick's ODOM_STATUS summary and page 2 s late: no judge says two firmwares
    (before: analyze FAILed "two firmwares answered on one node ID from t=4.920 s", the monitor
    and the bridge CONFLICT); each judges the pose right (the firmware is correct: run PASSed)."""
    log = tmp_path / "late_status.log"
    late_s = halted_mid_tick(drive, log, frozenset({STATUS_ID}))
    for stream, code, report in reported_analyses(log, tmp_path):
        assert report.get("two_sources") is None, (stream, report["two_sources"])
        assert code == 0, stream
    monitor, states = _monitor_states(log)
    assert "CONFLICT" not in states, states
    assert [e for e in monitor.events if e["kind"] in ("two sources", "uptime jump")] == []
    assert monitor.health(monitor.bus_time_s)["state"] == "DEGRADED"  # the firmware's word
    assert monitor.tracker.wrongs.count == 0
    bridge = bridge_of(log, "pmir", "exact")
    assert bridge.sources.conflict_from_s is None
    for tracker in (monitor.tracker, bridge.tracker):
        assert tracker.vs_reference.max_dpos_m < 1e-4, late_s
    # the opposite error: a pose 10 mm off after the halt still FAILs
    assert x_10_mm_off_fails(log, tmp_path / "x10.log", 6.0, 50) == []


def test_the_whole_tick_sent_after_the_halt_is_no_conflict(drive: Path, tmp_path: Path) -> None:
    """The rest of the tick (ODOM_POSE_Y, ODOM_TWIST, the summary, the page, NAV_STATUS) 2 s
    late, as ``kill -STOP`` left it in trial38's log: no two firmwares, analyze PASSes."""
    log = tmp_path / "late_tick.log"
    halted_mid_tick(drive, log, FIRMWARE_IDS)
    for stream, code, report in reported_analyses(log, tmp_path):
        assert report.get("two_sources") is None, (stream, report["two_sources"])
        assert code == 0, stream
    assert "CONFLICT" not in _monitor_states(log)[1]
    assert bridge_of(log, "pmir", "exact").sources.conflict_from_s is None


def _live_judged(log: Path, robot: str) -> list[tuple[str, float, float]]:
    """The live judges of ``log`` (the monitor, the bridge): each one's largest position error
    vs the reference and beyond its allowance (m)."""
    monitor = _monitor_states(log, robot)[0]
    bridge = bridge_of(log, robot, "exact")
    return [(name, t.vs_reference.max_dpos_m, t.max_beyond_allowance_m)
            for name, t in (("monitor", monitor.tracker), ("bridge", bridge.tracker))]


def _live_10_mm_off(log: Path, robot: str, tampered: Path) -> list[str]:
    """What is wrong with the live judges on ``log`` with X 10 mm off from 6 s on (``[]``:
    each says POSE WRONG by more than 5 mm beyond its allowance)."""
    assert raise_x_10_mm(log, tampered, 6.0) > 50
    wrong = [f"{name}: {beyond * 1e3:.4g} mm beyond" for name, _, beyond in
             _live_judged(tampered, robot) if beyond <= 5e-3]
    monitor = _monitor_states(tampered, robot)[0]
    if monitor.health(monitor.bus_time_s)["state"] != "POSE WRONG":
        wrong.append(f"monitor: {monitor.health(monitor.bus_time_s)['state']}")
    return wrong


@pytest.mark.parametrize("ids", [frozenset({0x201}), FIRMWARE_IDS], ids=["pose_y", "tick"])
@pytest.mark.parametrize("robot", ["pmir", "kobuki"])
def test_the_live_pose_after_a_pose_half_sent_after_the_halt_is_judged_right(
        request: pytest.FixtureRequest, robot: str, ids: frozenset[int], tmp_path: Path) -> None:
    """The halted tick's ODOM_POSE_Y (alone, or with the rest of its tick) 2 s after its
    ODOM_POSE_X: its Y, 1 ms before the next tick's, read queued, its sample was judged as a
    burst's and the silence told no stall (``livequeuedfirst``). Before: the monitor and the
    bridge POSE WRONG 63.999 mm (allowed 0.053 mm) on pmir, 226.2 mm on kobuki (its re-prime
    missed), on the correct firmware; analyze (whole and streamed) PASSed (6.8e-5 m). Now
    every judge agrees, and a pose 10 mm off after the halt still FAILs each."""
    drive = request.getfixturevalue("drive" if robot == "pmir" else "kobuki_drive")
    log = tmp_path / "late_y.log"
    halted_mid_tick(drive, log, ids)
    for stream, code, _ in reported_analyses(log, tmp_path):
        assert code == 0, stream
    for name, dpos_m, _ in _live_judged(log, robot):
        assert dpos_m < 1e-4, (name, dpos_m)
    # the resumed tick's pose judged by the next (``livestallfirst``: before, the late Y named
    # the pose before the silence a frame 16 on, and the first after it went unjudged on pmir)
    verdict = _monitor_states(log, robot)[0].first_after.verdict
    assert (verdict.judged, verdict.unjudged) == (1, 0), verdict
    assert max(verdict.worst_position_m, verdict.worst_heading_rad) <= 0, verdict
    assert _live_10_mm_off(log, robot, tmp_path / "x10.log") == []
    assert x_10_mm_off_fails(log, tmp_path / "x10a.log", 6.0, 50) == []


@pytest.mark.xfail(strict=True, reason=(
    "live judges only (monitor, bridge): the resumed tick's ODOM_POSE_X (4.921 s, its Y named "
    "no frame by the queued chain) 10 mm off PASSes them; analyze FAILs it as a lone half "
    "(lonehalves: 9.97 mm beyond). Traced: livelone judges a lone half only where the reference "
    "at its frame is the latest sample's, and this one lies between the halted tick's sample "
    "(left out, livequeuedfirst) and the placement at the next; livestallfirst judges it by the "
    "next pose alone, beyond the tolerance on one side: not judged (stallfirst.decided)"))
def test_the_resumed_tick_s_lone_x_10_mm_off_fails_live(drive: Path, tmp_path: Path) -> None:
    log, off = tmp_path / "late_y.log", tmp_path / "off.log"
    halted_mid_tick(drive, log, frozenset({0x201}))
    raise_first_x(log, off, 100, HALT_S + 2.0, HALT_S + 2.02)
    assert fails_by_position(off, tmp_path) == []
    for name, _, beyond_m in _live_judged(off, "pmir"):
        assert beyond_m > 5e-3, (name, beyond_m)


def test_the_live_reprime_after_a_summary_sent_after_the_halt_is_followed(
        kobuki_drive: Path, tmp_path: Path) -> None:
    """Kobuki: the halted tick's summary and page 2 s late. The live judges measured the
    stall from the firmware's last ODOM_STATUS heard, that late summary, 1 ms before the
    stall's first sample: no long stall, the re-prime it declared (COUNTER_RESET) missed.
    Before: POSE WRONG 184.6 mm, -3073.8 mrad (allowed 0.006 mm) on the correct firmware;
    analyze PASSed (6.8e-5 m). Now from the last ODOM_STATUS made before the halt
    (``livefirst.FirstStall.made_before``), as ``stallreprime.around`` reads the summaries."""
    log = tmp_path / "late_status.log"
    halted_mid_tick(kobuki_drive, log, frozenset({STATUS_ID}))
    monitor, states = _monitor_states(log, "kobuki")
    assert "CONFLICT" not in states, states
    assert bridge_of(log, "kobuki", "exact").sources.conflict_from_s is None
    assert [e["kind"] for e in monitor.events if e["kind"].startswith("stall_reprime")] == [
        "stall_reprime"]
    for name, dpos_m, _ in _live_judged(log, "kobuki"):
        assert dpos_m < 1e-4, (name, dpos_m)
    assert _live_10_mm_off(log, "kobuki", tmp_path / "x10.log") == []


def test_a_second_firmware_s_summary_is_not_passed_over() -> None:
    """The rule's edges (``haltedsend``): made before a silence and continuing the sequence,
    passed over; not continuing it, going back, or with no silence before it (two firmwares
    interleaving): not."""
    offset_s, last = -0.5, (3, "OK")
    before = (3.4, 13)  # the ODOM_STATUS frame heard before it: bus time, COUNTER
    assert sent_after_halt((5.6, 3, "OK", 14), offset_s, UPTIME_MATCH_S, last, before)
    assert not sent_after_halt((5.6, 3, "OK", 15), offset_s, UPTIME_MATCH_S, last, before)
    assert not sent_after_halt((5.6, 2, "OK", 14), offset_s, UPTIME_MATCH_S, last, before)
    assert not sent_after_halt((5.6, 3, "INIT", 14), offset_s, UPTIME_MATCH_S, last, before)
    assert not sent_after_halt((5.6, 3, "OK", 14), offset_s, UPTIME_MATCH_S, last, (5.55, 13))
    assert not sent_after_halt((5.6, 3, "OK", None), offset_s, UPTIME_MATCH_S, last, before)
    assert not sent_after_halt((3.45, 3, "OK", 14), offset_s, UPTIME_MATCH_S, last, before)


def _burst(src: Path, dst: Path, from_s: float, to_s: float, x_on_time: bool
           ) -> list[tuple[int, float]]:
    """Copy ``src`` to ``dst`` with the firmware's pose frames (ODOM_POSE_X, ODOM_POSE_Y,
    ODOM_TWIST) of ``from_s`` to ``to_s`` s held by the bus and let out in a burst, 0.2 ms
    apart, just after the encoder frame of ``to_s`` (encoder frames on time); ``x_on_time``:
    the first ODOM_POSE_X sent on time (the node went bus-off after it). The burst's frames:
    CAN ID, bus time (s after the first frame)."""
    msgs = list(can.LogReader(str(src)))
    t0 = msgs[0].timestamp
    held = [m for m in msgs if m.arbitration_id in (0x200, 0x201, 0x202)
            and from_s <= m.timestamp - t0 < to_s][int(x_on_time):]
    assert len(held) > 10, len(held)
    rest = [m for m in msgs if all(m is not h for h in held)]
    k = next(i for i, m in enumerate(rest) if m.timestamp - t0 > to_s)
    for i, msg in enumerate(held):
        msg.timestamp = t0 + to_s + (i + 1) * 2e-4
    assert rest[k].timestamp > held[-1].timestamp
    with can.Logger(str(dst)) as out:
        for msg in [*rest[:k], *held, *rest[k:]]:
            out.on_message_received(msg)
    return [(m.arbitration_id, m.timestamp - t0) for m in held]


@pytest.mark.parametrize("x_on_time", [False, True], ids=["whole", "x_on_time"])
def test_a_burst_after_the_bus_held_the_poses_is_no_stall(
        drive: Path, tmp_path: Path, x_on_time: bool) -> None:
    """The other side of ``livequeuedfirst``: poses the bus held 90 ms (no ODOM_POSE_Y while
    the encoder frames came on time) and let out at once, the first tick's X on time or not:
    the burst's first sample, queued after a silence, is a burst's (the next sample 0.6 ms
    after it), judged as one, as ``analyze`` judges it: no sample left out, no placement, the
    pose right. The burst's second ODOM_POSE_X alone (its Y lost) 10 mm off: a lone half every
    judge FAILs (judged after the first sample, whose hold ends before: ``paired``)."""
    log = tmp_path / "burst.log"
    burst = _burst(drive, log, 6.0, 6.09, x_on_time)
    for stream, code, _ in reported_analyses(log, tmp_path):
        assert code == 0, stream
    kept = _monitor_states(drive)[0].tracker
    monitor = _monitor_states(log)[0].tracker
    assert monitor.vs_reference.samples == kept.vs_reference.samples
    assert monitor.stall.stalls == kept.stall.stalls
    for name, dpos_m, _ in _live_judged(log, "pmir"):
        assert dpos_m < 1e-4, (name, dpos_m)
    x_s = [t for can_id, t in burst if can_id == 0x200][1]  # the second tick's halves
    y_s = next(t for can_id, t in burst if can_id == 0x201 and t > x_s)
    lone = tmp_path / "lone.log"
    assert drop_frames(log, tmp_path / "y_lost.log", ("ODOM_POSE_Y",), y_s - 5e-5,
                       y_s + 5e-5) == 1
    assert raise_raw(tmp_path / "y_lost.log", lone, "ODOM_POSE_X", POSE_X, 100, x_s - 5e-5,
                     x_s + 5e-5) == 1
    assert fails_by_position(lone, tmp_path) == []
    for name, _, beyond_m in _live_judged(lone, "pmir"):
        assert beyond_m > 5e-3, (name, beyond_m)
