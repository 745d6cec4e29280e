"""Every figure issue #11's closing note must show, from one reproducible run; asserts nothing.

1. the judge's own error after 100 km, from power-up and mid-drive (``bench/judge_error.py``);
2. ``odocan calibrate`` on kobuki (E_d 1.002, E_b 1.01, seed 3), on a 32 m pmir square, and the
   refused case (E_d = E_b = 1.9): estimates vs injected, E_max,syst before -> after, exit code;
3. LINEAR_VEL and ANGULAR_VEL on the bus after gaps of 16, 31 and 100 lost encoder frames
   (bus-off of the sim's controller in the lockstep rig) vs the truth's speed over the same
   span, SATURATION, and ``analyze``'s verdict on the run;
4. the time from firmware silence to STALE: ``odocan sim`` and ``odocan firmware`` as processes
   on udp_multicast (a fresh loopback group and port), the firmware killed with SIGKILL, the
   live judge (``BusMonitor``) fed here and ``odocan monitor --json`` as a third process;
5. the stall, reboot, counter-reset, 8 000 frames/s forgery and duplicate-node cases in the
   lockstep rig (``tests/test_health_rig.py``'s scenarios): the host's verdict, the firmware's
   states and error bits, the pose error vs the host's reference, an independent float64 arc
   integration of the robot's counts and the truth; and a SIGSTOP of the firmware process for
   2 s as the cross-check with real processes.

Run: ``.venv/bin/python bench/verdicts.py [--quick] [--only judge,calibrate,twist,stale,faults]``
(about 2 minutes of CPU in full; ``--quick``: shorter drives, one square per direction).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import secrets
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from unittest import mock

import can

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bench.judge_error import LONG_STEPS, judge_error_rows
from odocan.firmware.errors import ErrorFlag
from odocan.host.experiments import umbmark
from odocan.host.io.logs import FrameCollector
from odocan.host.judge.analysis import analyze
from odocan.host.judge.monitor import BusMonitor
from odocan.sim import errors as sim_errors
from odocan.sim.contract import database
from odocan.sim.faults import FaultSpec
from odocan.sim.pose import wrap_angle
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.robot import load
from odocan.sim.vehicle import Vehicle
from tests.dbc_typed import numbers
from tests.test_forged_pairing import RecordingWatch, run_one_forged_frame
from tests.test_health_rig import (
    Watch,
    run_counter_reset,
    run_duplicate,
    run_forgery,
    run_reboot,
    run_silence,
    run_stall,
)

ROOT = Path(__file__).resolve().parent.parent
CLI = [sys.executable, "-m", "odocan"]
SECTIONS = ("judge", "calibrate", "twist", "stale", "faults")
DB = database()
ENCODERS, TWIST, STATUS = (DB.get_message_by_name(n) for n in
                           ("WHEEL_ENCODERS", "ODOM_TWIST", "ODOM_STATUS"))
FIRMWARE_IDS = {m.frame_id for m in DB.messages if m.senders == ["ODOM_MCU"]}  # not MOTOR_CMD:
# the scenario driver sends it in open loop
START_TIMEOUT_S = 30.0  # interpreter and imports of two processes on a loaded 2-core machine


def _env() -> dict[str, str]:
    """This tree first on the path of every ``odocan`` process started here."""
    path = os.environ.get("PYTHONPATH")
    return {**os.environ, "PYTHONPATH": str(ROOT) + (os.pathsep + path if path else "")}


# --- 1. the judge's own error -----------------------------------------------------------------


def section_judge(quick: bool) -> None:
    steps = 5_610 if quick else LONG_STEPS
    print(f"\n1. The judge's own error (bench/judge_error.py --steps {steps}; LSB = 0.1 mm)")
    print(f"  {'robot':8} {'integrator':10} {'start':9} {'km':>6} {'own error':>11} "
          f"{'on-board vs ref':>15}  verdict | {'live own error':>14} {'on-board vs ref':>15}  "
          f"live verdict")
    for r in judge_error_rows(steps):
        print(f"  {r.robot:8} {r.integrator:10} {r.start:9} {r.km:6.1f} "
              f"{r.own_error_lsb:7.4f} LSB {r.vs_reference_lsb:11.3f} LSB  "
              f"{'PASS' if r.passed else 'FAIL':7} | {r.live_own_error_lsb:10.4f} LSB "
              f"{r.live_vs_reference_lsb:11.3f} LSB  {r.live_state}")


# --- 2. calibrate ------------------------------------------------------------------------------


@dataclass(frozen=True)
class CalibrationRow:
    """One calibration: the estimates against the injected errors, E_max,syst, the verdict."""

    case: str
    injected: tuple[float, float]
    estimated: tuple[float, float]
    emax_before_m: float
    emax_after_m: float
    exit_code: int
    reasons: list[str]


def _calibrate_cli(case: str, argv: list[str], runs: int) -> CalibrationRow:
    """``odocan calibrate ARGV --runs RUNS --report R`` as a process: its report and exit code."""
    with tempfile.TemporaryDirectory() as folder:
        report_path = Path(folder) / "calibrate.json"
        done = subprocess.run([*CLI, "calibrate", *argv, "--runs", str(runs), "--report",
                               str(report_path)], capture_output=True, text=True, env=_env(),
                              cwd=ROOT, check=False)
        if not report_path.exists():
            raise RuntimeError(f"calibrate {argv} exit {done.returncode}: {done.stderr.strip()}")
        report = json.loads(report_path.read_text())
    return CalibrationRow(
        case, (report["injected"]["ed"], report["injected"]["eb"]),
        (report["estimated"]["ed"], report["estimated"]["eb"]),
        report["emax_before_m"], report["emax_after_m"], done.returncode, report["faults"])


def _calibrate_api(case: str, robot: str, errors: str, side_m: float, runs: int) -> CalibrationRow:
    """What ``odocan calibrate`` runs (``umbmark.calibrate``, ``calibration_faults``, exit 1 on
    a fault), in this process: its ``--side`` stops at 20 m."""
    profile, model = load(robot), sim_errors.parse(errors)
    cal = umbmark.calibrate(profile, model, 3, side_m=side_m, runs_per_direction=runs)
    reasons = umbmark.calibration_faults(cal, profile)
    return CalibrationRow(case, (model.ed, model.eb), cal.estimated, cal.before.emax_m,
                          cal.after.emax_m, 1 if reasons else 0, reasons)


def section_calibrate(quick: bool) -> None:
    runs = 1 if quick else umbmark.RUNS_PER_DIRECTION
    print(f"\n2. Calibrate (seed 3, {runs} square(s) per direction; exit 0 PASS, 1 FAIL)")
    rows = [
        _calibrate_cli("kobuki 4 m, CLI", ["--robot", "kobuki", "--errors", "ed=1.002,eb=1.01",
                                          "--seed", "3"], runs),
        _calibrate_api("pmir 32 m, API", "pmir", "ed=1.002,eb=1.01", 32.0, runs),
        _calibrate_cli("kobuki 1.9/1.9, CLI", ["--robot", "kobuki", "--errors", "ed=1.9,eb=1.9",
                                              "--seed", "3"], runs),
    ]
    print(f"  {'case':20} {'E_d inj -> est':>20} {'E_b inj -> est':>20} "
          f"{'E_max,syst before -> after':>30} exit")
    for r in rows:
        emax = f"{r.emax_before_m * 1e3:.1f} -> {r.emax_after_m * 1e3:.2f} mm"
        ratio = r.emax_before_m / r.emax_after_m if r.emax_after_m else math.inf
        cut = f"({ratio:.1f}x)" if ratio < 10 else f"({ratio:.0f}x)"
        print(f"  {r.case:20} {r.injected[0]:6.4f} -> {r.estimated[0]:8.6f} "
              f"{r.injected[1]:6.4f} -> {r.estimated[1]:8.6f} {emax:>22} {cut:>7} {r.exit_code:4}")
        for reason in r.reasons:
            print(f"    reason: {reason}")
        if r.injected != (1.0, 1.0) and not r.reasons:
            off = [abs(e - i) / abs(i - 1.0) for e, i in zip(r.estimated, r.injected, strict=True)]
            print(f"    estimate off by {off[0]:.2%} (E_d) and {off[1]:.2%} (E_b) of the "
                  "injected deviation")


# --- 3. the twist after a gap ------------------------------------------------------------------

RECOVERY_S = 128 * 11 / 500_000  # bus-off recovery at the rig's 500 kbit/s (sim/busoff.py)
GAP_AT_S = 2.0  # the straight scenario cruises from about 0.3 s to 4 s


@dataclass
class TwistWatch(can.Listener):
    """The host's frames of a rig run with the truth at every encoder frame heard."""

    vehicle: Vehicle | None = None
    encoders: list[tuple[float, int, float, float]] = field(default_factory=list)  # t, COUNTER,
    # truth distance (m) and heading (rad) at that frame
    twists: list[tuple[float, int, float, float]] = field(default_factory=list)  # t, ENC_COUNTER,
    # LINEAR_VEL, ANGULAR_VEL
    masks: list[int] = field(default_factory=list)  # ERROR_MASK of each summary

    def on_message_received(self, msg: can.Message) -> None:
        if msg.arbitration_id == ENCODERS.frame_id and self.vehicle is not None:
            truth = self.vehicle.truth()  # the vehicle is at this frame's instant until next tick
            counter = int(numbers(DB, ENCODERS.frame_id, msg.data)["COUNTER"])
            self.encoders.append((msg.timestamp, counter, truth.distance_m, truth.heading_rad))
        elif msg.arbitration_id == TWIST.frame_id:
            s = numbers(DB, TWIST.frame_id, msg.data)
            self.twists.append((msg.timestamp, int(s["ENC_COUNTER"]), float(s["LINEAR_VEL"]),
                                float(s["ANGULAR_VEL"])))
        elif msg.arbitration_id == STATUS.frame_id and msg.data[1] >> 4 == 0:
            self.masks.append(int(numbers(DB, STATUS.frame_id, msg.data)["ERROR_MASK"]))


def _twist_after_gap(watch: TwistWatch) -> dict[str, float]:
    """The longest encoder gap, the first twist naming a frame j after it, and the truth's mean
    speeds over the firmware's step to j (from the frame it took before j, as
    tests/test_health_twist.py reads it: k - 1 unless frame k repeated k - 1's COUNTER)."""
    enc = watch.encoders
    k = max(range(1, len(enc)), key=lambda n: enc[n][0] - enc[n - 1][0])
    periods = round((enc[k][0] - enc[k - 1][0]) / 0.01)
    named = {e[1]: j for j, e in enumerate(enc[k:k + 3], k)}
    v, w, j = next((v, w, named[c]) for t, c, v, w in watch.twists
                   if t > enc[k][0] and c in named)
    i = k - 1 if j == k or (j == k + 1 and periods % 16 == 0) else j - 1
    span_s = enc[j][0] - enc[i][0]
    return {"lost": periods - 1, "linear": v, "angular": w,
            "truth_v": (enc[j][2] - enc[i][2]) / span_s,
            "truth_w": wrap_angle(enc[j][3] - enc[i][3]) / span_s}


def _gap_run(scenario: str, lost: int) -> tuple[dict[str, float], dict[str, Any], bool, bool]:
    """pmir on ``scenario``; the sim's controller bus-off at 2 s for ``lost`` encoder frames.
    Returns the twist after the gap, analyze's twist check, SATURATION ever set (the sticky
    ERROR_MASK bit on ODOM_STATUS), analyze's verdict."""
    busoff_s = (lost - 1) * 0.01 + 0.005 - RECOVERY_S
    faults = FaultSpec.parse(f"busoff={GAP_AT_S}:{busoff_s:.4f}")
    watch, collector = TwistWatch(), FrameCollector()
    config = RigConfig(load("pmir"), "exact", scenario, 1, faults=faults, duration_s=4.5)
    with LockstepRig(config, [watch, collector]) as rig:
        watch.vehicle = rig.vehicle
        rig.run()
    result = analyze(collector.arrays(), load("pmir"))
    saturation = any(m & int(ErrorFlag.SATURATION) for m in watch.masks)
    return (_twist_after_gap(watch), result.report["onboard_twist_vs_reference"], saturation,
            result.passed)


def section_twist(quick: bool) -> None:
    print("\n3. ODOM_TWIST after a gap (pmir, lockstep rig, the sim's controller bus-off at 2 s; "
          "truth: mean over the firmware's step)")
    print(f"  {'scenario':8} {'lost':>4} {'LINEAR_VEL':>10} {'truth v':>8} {'ANGULAR_VEL':>11} "
          f"{'truth w':>8}  SATURATION  twist check   analyze")
    for scenario in ("straight", "circle"):
        for lost in (16, 31, 100):
            gap, twist, saturation, passed = _gap_run(scenario, lost)
            check = "PASS" if twist["passed"] else (
                f"FAIL {twist['max_linear_excess_mps']:.3f} m/s")
            print(f"  {scenario:8} {gap['lost']:4.0f} {gap['linear']:7.3f} m/s "
                  f"{gap['truth_v']:8.4f} {gap['angular']:7.3f} r/s {gap['truth_w']:8.4f}  "
                  f"{'set' if saturation else 'not set':10}  {check:12}  "
                  f"{'PASS' if passed else 'FAIL'}")


# --- 4. processes: a SIGSTOP of the firmware, then its silence ---------------------------------

STOP_S = 2.0  # the firmware's SIGSTOP
AFTER_STOP_S = 4.0  # watched after SIGCONT
AFTER_KILL_S = 3.0  # watched after SIGKILL, then the monitor process is asked for its JSON


def _udp_channel() -> tuple[list[str], dict[str, Any]]:
    """CLI options and can.Bus keywords of a fresh loopback-only udp_multicast channel (a group
    and a port of its own, TTL 0: nothing leaves the machine; as tests/test_realtime.py)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    group = f"239.255.{secrets.randbelow(250) + 1}.{secrets.randbelow(250) + 1}"
    kwargs = {"interface": "udp_multicast", "channel": group, "port": port, "hop_limit": 0}
    argv = ["-i", "udp_multicast", "-c", group, "--bus-arg", f"port={port}",
            "--bus-arg", "hop_limit=0"]
    return argv, kwargs


@contextmanager
def _process(args: list[str]) -> Iterator[subprocess.Popen[str]]:
    """``odocan ARGS`` as a process of its own; killed (by its pid) if still running at the end."""
    proc = subprocess.Popen([*CLI, *args], cwd=ROOT, env=_env(), text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.communicate()


@dataclass
class LiveJudge:
    """The live judge (``BusMonitor``, as ``odocan monitor`` runs it) fed from a real bus in real
    time, with its verdict sampled every few ms."""

    bus: can.BusABC
    monitor: BusMonitor = field(default_factory=lambda: BusMonitor(load("pmir"), None))
    verdicts: list[tuple[float, str, str]] = field(default_factory=list)  # monotonic s, state,
    # the firmware's (STATE, REASON) as last reported
    last_firmware_s: float = -math.inf  # monotonic time of the last firmware frame heard

    def pump(self, seconds: float, until: Callable[[], bool] = lambda: False) -> bool:
        """Feed what arrives for ``seconds`` or until ``until()``; True when ``until()`` held."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            msg = self.bus.recv(0.003)
            now = time.monotonic()
            if msg is not None and not msg.is_error_frame:
                self.monitor.feed(msg, now_s=now)
                if msg.arbitration_id in FIRMWARE_IDS:
                    self.last_firmware_s = now
            status = self.monitor.status
            firmware = f"{status.get('state', '?')} {status.get('reason', '')}".strip()
            self.verdicts.append((now, self.monitor.health(now)["state"], firmware))
            if until():
                return True
        return False

    def state(self) -> str:
        return self.verdicts[-1][1] if self.verdicts else "NO FIRMWARE"

    def timeline(self, since_s: float) -> str:
        """The verdicts (and the firmware's own state) since ``since_s``, repeats merged, with
        the seconds from ``since_s`` at which each began."""
        merged: list[tuple[float, str, str]] = []
        for t, verdict, firmware in self.verdicts:
            if t >= since_s and (not merged or merged[-1][1:] != (verdict, firmware)):
                merged.append((t, verdict, firmware))
        return ", ".join(f"{t - since_s:+.2f} s {v} (fw {f})" for t, v, f in merged)

    def errors_m(self) -> tuple[float, float]:
        """The latest on-board vs reference and vs truth position errors, m."""
        tracker = self.monitor.tracker
        return (tracker.vs_reference.latest.get("dpos_m", math.nan),
                tracker.vs_truth.latest.get("dpos_m", math.nan))


def _probe(kwargs: dict[str, Any]) -> can.BusABC | str:
    """The listener's handle, or why udp_multicast cannot be used here."""
    try:
        listener, probe = can.Bus(**kwargs), can.Bus(**kwargs)
    except (can.CanError, OSError, ImportError) as exc:
        return f"udp_multicast cannot be opened here: {exc}"
    try:
        probe.send(can.Message(arbitration_id=0x7FF, data=bytes(8), is_extended_id=False))
        if listener.recv(2.0) is None:
            listener.shutdown()
            return "udp_multicast does not loop back on this machine"
    finally:
        probe.shutdown()
    return listener


def section_stale(quick: bool) -> None:
    print("\n4. Processes on udp_multicast (odocan firmware + sim --scenario circle + monitor "
          "--json; the live judge fed here in real time)")
    argv, kwargs = _udp_channel()
    bus = _probe(kwargs)
    if isinstance(bus, str):
        print(f"  skipped: {bus}")
        return
    try:
        with (_process(["firmware", *argv]) as firmware,
              _process(["sim", "--scenario", "circle", *argv]) as sim,
              _process(["monitor", "--json", *argv]) as monitor):
            _stall_and_silence(LiveJudge(bus), firmware, sim, monitor)
    finally:
        bus.shutdown()


def _stall_and_silence(judge: LiveJudge, firmware: subprocess.Popen[str],
                       sim: subprocess.Popen[str], monitor: subprocess.Popen[str]) -> None:
    """OK first; SIGSTOP the firmware 2 s, SIGCONT, 4 s; then SIGKILL it and time STALE."""
    if not judge.pump(START_TIMEOUT_S, lambda: judge.state() == "OK"):
        print(f"  the live judge never said OK in {START_TIMEOUT_S:g} s: {judge.state()}")
        return
    judge.pump(1.0)
    overflowed = judge.monitor.status.get("overflowed_frames", 0)
    dref, dtruth = judge.errors_m()
    print(f"  before: verdict {judge.state()}; on-board vs reference {dref * 1e3:.3f} mm, vs "
          f"truth {dtruth * 1e3:.3f} mm")
    stopped_at = time.monotonic()
    os.kill(firmware.pid, signal.SIGSTOP)
    judge.pump(STOP_S)
    os.kill(firmware.pid, signal.SIGCONT)
    judge.pump(AFTER_STOP_S)
    dref, dtruth = judge.errors_m()
    status = judge.monitor.status
    print(f"  SIGSTOP firmware {STOP_S:g} s: {judge.timeline(stopped_at)}")
    print(f"    end: verdict {judge.state()}, firmware {status.get('state')} "
          f"{status.get('reason')}, errors {status.get('errors')}, mailbox overflows "
          f"{status.get('overflowed_frames', 0) - overflowed}; on-board vs reference "
          f"{dref * 1e3:.3f} mm, vs truth {dtruth * 1e3:.3f} mm")
    os.kill(firmware.pid, signal.SIGKILL)
    killed_at = time.monotonic()
    judge.pump(AFTER_KILL_S)
    stale_at = min((t for t, v, _ in judge.verdicts if t > killed_at and v == "STALE"),
                   default=math.nan)
    age = judge.monitor.health()["nodes"]["ODOM_MCU"]
    print(f"  SIGKILL firmware: STALE {stale_at - judge.last_firmware_s:.3f} s after its last "
          f"frame heard ({stale_at - killed_at:.3f} s after the kill; the DBC timeout "
          f"{age['timeout_s']:.2f} s); {AFTER_KILL_S:g} s later: {judge.state()}, age "
          f"{age['age_s']:.2f} s, why: {judge.monitor.health()['why']}")
    monitor.send_signal(signal.SIGINT)
    out, err = monitor.communicate(timeout=30)
    _print_monitor_json(out, err, monitor.returncode)
    sim.send_signal(signal.SIGTERM)
    _, sim_err = sim.communicate(timeout=30)
    print(f"  the sim process: {sim_err.strip().splitlines()[-1] if sim_err.strip() else '-'}")


def _print_monitor_json(out: str, err: str, code: int) -> None:
    """What ``odocan monitor --json`` said when asked (SIGINT) 3 s after the kill."""
    try:
        health = json.loads(out)["health"]
    except (ValueError, KeyError):
        print(f"  odocan monitor --json: exit {code}, no JSON ({err.strip()[-200:]})")
        return
    node = health["nodes"].get("ODOM_MCU", {})
    events = ", ".join(f"{e['kind']} ({e['detail']})" for e in health["events"]) or "none"
    print(f"  odocan monitor --json (exit {code}), {AFTER_KILL_S:g} s after the kill: state "
          f"{health['state']}, ODOM_MCU age {node.get('age_s', math.nan):.2f} s, why: "
          f"{'; '.join(health['why'])}; events: {events}")

# --- 5. fault cases in the lockstep rig ---------------------------------------------------------


def _merged(changes: list[tuple[float, str]], limit: int = 8) -> str:
    """``t s state`` at each change of state, the first ``limit`` of them."""
    merged = [(t, v) for n, (t, v) in enumerate(changes) if n == 0 or v != changes[n - 1][1]]
    shown = ", ".join(f"{t:.2f} s {v}" for t, v in merged[:limit])
    return shown + (f", ... ({len(merged) - limit} more changes)" if len(merged) > limit else "")


def _truth_error_m(watch: Watch) -> float:
    """|on-board pose in the firmware - the vehicle's true pose| now, m (same start frame)."""
    odo, truth = watch.rig.ecu.odometry, watch.rig.vehicle.truth()
    return math.hypot(odo.x_q40_m / 2**40 - truth.x_m, odo.y_q40_m / 2**40 - truth.y_m)


def _print_case(name: str, watch: Watch, restarted: bool = False) -> None:
    """What the host ends in, the firmware's states and bits, the pose errors at the end."""
    tracker, status = watch.monitor.tracker, watch.monitor.status
    vs_ref, vs_truth = tracker.vs_reference, tracker.vs_truth
    events = ", ".join(e["kind"] for e in watch.monitor.events) or "none"
    health = watch.monitor.health(watch.verdicts[-1][0])
    independent = "n/a: the pose restarted" if restarted else f"{watch.pose_error_m() * 1e3:.3f} mm"
    direct = "n/a: the pose restarted" if restarted else f"{_truth_error_m(watch) * 1e3:.3f} mm"
    print(f"  {name}")
    print(f"    host verdicts: {_merged(watch.verdicts)}")
    print(f"    firmware (ODOM_STATUS): {' -> '.join(f'{s} {r}' for s, r in watch.states())}; "
          f"error bits at the end {status.get('errors')}")
    print(f"    events: {events}; ends in {health['state']}"
          + (f" ({'; '.join(health['why'])})" if health["why"] else ""))
    dref_m = vs_ref.latest.get("dpos_m", math.nan)
    print(f"    pose at the end: vs the host's reference {dref_m * 1e3:.3f} mm (max "
          f"{vs_ref.max_dpos_m * 1e3:.3f}), vs truth (host) "
          f"{vs_truth.latest.get('dpos_m', math.nan) * 1e3:.3f} mm; independent float64 "
          f"{independent}, vs the vehicle's truth {direct}")


def _one_forged_frame() -> None:
    """tests/test_forged_pairing.py's case: what analyze and the live judge say of it."""
    for ahead in (1, 2, 3):
        watch, collector = run_one_forged_frame(ahead)
        result = analyze(collector.arrays(), load("pmir"))
        verdicts = sorted({v for _, v in watch.verdicts})
        print(f"  one forged encoder frame (CRC right, COUNTER +{ahead}, in a genuine frame's "
              f"tick): firmware pose vs independent {watch.pose_error_m() * 1e3:.3f} mm; "
              f"analyze {'PASS' if result.passed else 'FAIL'} (on-board vs reference "
              f"{result.report['onboard_vs_reference']['max_position_error_m'] * 1e3:.3f} mm); "
              f"live verdicts {verdicts}")


def section_faults(quick: bool) -> None:
    print("\n5. Fault cases (pmir circle, lockstep rig, tests/test_health_rig.py's scenarios; "
          "the live judge BusMonitor fed every frame)")
    watch, _ = run_stall()
    _print_case("stall: the MCU halted 200 ticks (2 s) at 5 s, 3 s more", watch)
    watch, _ = run_reboot()
    _print_case("reboot: a new firmware on the board at 5 s, 3 s more", watch, restarted=True)
    watch, figures = run_counter_reset()
    print(f"  counter reset at 8 s (before the host's ODOM_SET_POSE APPLY): firmware "
          f"{figures['states'][-1]}, host {figures['verdict']}, pose vs independent float64 "
          f"{figures['pose_error_m'] * 1e3:.1f} mm, implausible steps refused "
          f"{figures['implausible']}")
    _print_case("counter reset: the motor controller restarted at 5 s; APPLY at 8 s, end 9 s",
                watch)
    seconds = 2.0 if quick else 4.0
    collector = FrameCollector()
    with mock.patch.object(RecordingWatch, "collector", collector), \
            mock.patch("tests.test_health_rig.Watch", RecordingWatch):
        watch, figures = run_forgery(seconds)
    _print_case(f"forgery: 8000 random frames/s on WHEEL_ENCODERS from 2 s for {seconds:g} s "
                f"(mailbox overflows {figures['overflows']}, implausible steps refused "
                f"{figures['implausible']})", watch)
    result = analyze(collector.arrays(), load("pmir"))
    vs_ref = result.report["onboard_vs_reference"]
    print(f"    analyze of the same frames: {'PASS' if result.passed else 'FAIL'} (position "
          f"{vs_ref['max_position_error_m'] * 1e3:.3f} mm, allowed "
          f"{vs_ref['loss_allowance_m'] * 1e3:.1f} mm for frames lost on board; heading "
          f"{vs_ref['max_heading_error_rad'] * 1e3:.3f} mrad)")
    seconds = 5.0 if quick else 20.0
    watch, figures = run_forgery(seconds, 8)
    _print_case(f"forgery: 800 random frames/s from 2 s for {seconds:g} s (overflows "
                f"{figures['overflows']}, implausible steps refused {figures['implausible']})",
                watch)
    _one_forged_frame()
    watch, _ = run_duplicate()
    _print_case("duplicate: a second firmware on the same IDs from 3 s, end 6 s", watch)
    watch, to_stale_s = run_silence()
    print(f"  silence in the rig (halted for good at 5 s): STALE {to_stale_s:.3f} s after the "
          "last firmware frame")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="shorter drives, one square a way")
    parser.add_argument("--only", default=",".join(SECTIONS),
                        help=f"comma-separated sections (default: {','.join(SECTIONS)})")
    args = parser.parse_args()
    chosen = [s for s in args.only.split(",") if s]
    unknown = set(chosen) - set(SECTIONS)
    if unknown:
        parser.error(f"unknown section(s) {', '.join(sorted(unknown))}")
    runs: dict[str, Callable[[bool], None]] = {
        "judge": section_judge, "calibrate": section_calibrate, "twist": section_twist,
        "stale": section_stale, "faults": section_faults}
    start_cpu, start_wall = time.process_time(), time.perf_counter()
    for name in SECTIONS:
        if name in chosen:
            runs[name](args.quick)
    print(f"\n(this process {time.process_time() - start_cpu:.1f} s CPU, "
          f"{time.perf_counter() - start_wall:.1f} s wall; the odocan processes it started not "
          "included)")


if __name__ == "__main__":
    main()
