"""A fleet across processes and machines: shards and their robot ids, the per-robot verdict, the
workers' aggregated report, and ``odocan fleet --workers/--shard/--port`` end to end on the
embedded broker in its own process (real spawned workers, real MQTT connections)."""

from __future__ import annotations

import json
import math
import os
import signal
import socket
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest

from odocan.host.cli.app import main
from odocan.host.judge.analysis import HEADING_LSB_RAD, POSITION_LSB_M
from odocan.host.judge.livepose import ErrorStats, FramePose
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt import fleetrun
from odocan.host.mqtt.bridge import RobotEndpoint
from odocan.host.mqtt.broker import LOOPBACK, free_loopback_port
from odocan.host.mqtt.fleetjudge import judge_robot
from odocan.host.mqtt.fleetrun import failures
from odocan.host.mqtt.shards import Shard, aggregate, embedded_broker, split
from odocan.sim import fleet as sim_fleet
from odocan.sim import robot
from odocan.sim.board import TICK_S
from odocan.sim.fleet import Fleet, FleetConfig, frame_fields
from tests.fleet_judged import wait_until_judged
from tests.fleet_run_until import pace_never_late
from tests.requires import require_executables

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("total", [1, 2, 5, 7, 100, 101])
@pytest.mark.parametrize("parts", [1, 2, 3, 7])
def test_split_covers_every_robot_once_in_near_equal_slices(total: int, parts: int) -> None:
    slices = split(total, parts)
    indices = [first + i for first, count in slices for i in range(count)]
    assert indices == list(range(total))
    sizes = [count for _, count in slices]
    assert max(sizes) - min(sizes) <= 1


def test_shard_parse_and_its_robots() -> None:
    assert Shard.parse("2/3") == Shard(2, 3)
    assert Shard(2, 3).robots(10) == (3, 3)
    assert Shard(3, 3).robots(10) == (6, 4)
    not_k_of_n = r"expected K/N \(part K of N"
    for bad, says in (("3", not_k_of_n), ("1/", not_k_of_n), ("/2", not_k_of_n),
                      ("a/b", not_k_of_n), ("0/2", r"K must be in \[1, 2\], got 0/2"),
                      ("3/2", r"K must be in \[1, 2\], got 3/2"),
                      ("1/0", r"N must be in \[1, \d+\], got 1/0"), ("-1/2", not_k_of_n),
                      ("1/2/3", not_k_of_n)):
        with pytest.raises(ValueError, match=says):
            Shard.parse(bad)


def _frames(
    config: FleetConfig, ticks: int, *, stamped: bool = False
) -> dict[str, list[tuple[float, int, bytes]]]:
    """Each robot's host-observed frames (timestamp s or 0 unless ``stamped``, ID, data) over
    ``ticks`` fleet ticks, by name."""
    out: dict[str, list[tuple[float, int, bytes]]] = {}
    with Fleet(config) as fleet:
        for k in range(ticks):
            fleet.step(k)
            for index, frame in fleet.take_batch():
                t_s, can_id, data = frame_fields(frame)
                out.setdefault(fleet.names[index], []).append(
                    (t_s if stamped else 0.0, can_id, data))
    return out


@pytest.mark.parametrize("first", [1, 2])
def test_a_shards_robots_send_the_bytes_they_send_in_the_whole_fleet(first: int) -> None:
    """Names, seeds and tick phases are fleet-wide: sharding never changes a robot's frames."""
    whole = FleetConfig(robots=4, robot=robot.load("pmir"), seed=11)
    part = whole.shard(first, 2)
    shard_frames = _frames(part, 120)
    whole_frames = _frames(whole, 120)
    names = [f"robot{first + i + 1:03d}" for i in range(2)]
    assert sorted(shard_frames) == names
    for name in names:
        assert len(shard_frames[name]) > 100
        assert shard_frames[name] == whole_frames[name]
    assert shard_frames[names[0]] != whole_frames["robot001"]  # seeds differ: a real check


def test_every_robot_sends_the_same_bytes_on_either_transport() -> None:
    """``odocan fleet --transport``: python-can ``virtual`` and the ``odocan`` plugin carry the
    same frames, robot by robot, in the fleet's lockstep steps."""
    lean = FleetConfig(robots=3, robot=robot.load("pmir"), seed=3)
    frames = {t: _frames(replace(lean, transport=t), 150, stamped=True)
              for t in ("odocan", "virtual")}
    assert sorted(frames["odocan"]) == ["robot001", "robot002", "robot003"]
    for name, sent in frames["odocan"].items():
        assert len(sent) > 300
        assert frames["virtual"][name] == sent, name


def test_every_robot_sends_the_same_bytes_with_the_c_firmware() -> None:
    """``odocan fleet --firmware c``: the C port on every board, frame for frame the bytes (and
    timestamps) of the Python firmware's fleet."""
    require_executables("make", "cc", install="apt-get install gcc make")
    python = FleetConfig(robots=3, robot=robot.load("pmir"), seed=5)
    frames = {f: _frames(replace(python, firmware=f), 150, stamped=True) for f in ("python", "c")}
    assert sorted(frames["c"]) == ["robot001", "robot002", "robot003"]
    for name, sent in frames["python"].items():
        assert len(sent) > 300
        assert frames["c"][name] == sent, name


def test_fleet_on_python_cans_virtual_runs_and_judges_every_robot(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """On a clock never late (``PacedClock``): a loaded machine's tick 95 ms late halts the
    boards, and the poses of a halted robot are judged by stretch, not every one (33 of 38
    under load; tests/test_fleet_overload.py's subject, not this one's)."""
    pace_never_late(monkeypatch)
    report = tmp_path / "fleet.json"
    code = main(["fleet", "-n", "2", "--transport", "virtual", "--duration", "2", "--seed", "4",
                 "--max-miss-ratio", "1", "--report", str(report)])
    out, err = capsys.readouterr()
    data = json.loads(report.read_text())
    assert data["transport"] == "virtual"
    robots = data["per_robot"]
    assert list(robots) == ["robot001", "robot002"]
    # a loaded machine's skipped releases leave no robot unjudged (their samples sent late)
    assert code == 0, out + err
    # the run took its 2 s: every release of it was run or counted as skipped (on a loaded
    # machine fewer ticks run than the 200 of an idle one: 93 were seen)
    releases = data["ticks"] + data["skipped_releases"]
    assert releases >= 200
    for r in robots.values():
        assert r["verdict"] == "PASS", r["reason"]
        # one encoder frame per release, run or skipped (odd robots a tick out of phase), and
        # every pose the robot sent judged but the last, whose successor never came
        assert releases - 1 <= r["frames"]["WHEEL_ENCODERS"] <= releases
        assert r["frames"]["ODOM_POSE_Y"] > 0
        assert r["pose_vs_reference"]["samples"] >= r["frames"]["ODOM_POSE_Y"] - 1


def test_fleet_with_the_c_firmware_runs_and_judges_every_robot(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    require_executables("make", "cc", install="apt-get install gcc make")
    pace_never_late(monkeypatch)  # as above: a halt is test_fleet_overload's subject
    report = tmp_path / "fleet.json"
    code = main(["fleet", "-n", "2", "--firmware", "c", "--duration", "2", "--seed", "6",
                 "--max-miss-ratio", "1", "--report", str(report)])
    out, err = capsys.readouterr()
    data = json.loads(report.read_text())
    assert (data["firmware"], data["transport"]) == ("c", "odocan")
    robots = data["per_robot"]
    assert code == 0, out + err  # skipped releases too (their samples are sent late)
    for r in robots.values():
        assert r["verdict"] == "PASS", r["reason"]
        assert r["pose_vs_reference"]["samples"] > 20


def _stats(*errors: tuple[float, float]) -> ErrorStats:
    """ErrorStats of on-board poses off the reference by (dx m, dheading rad)."""
    stats = ErrorStats()
    for k, (dx_m, dh_rad) in enumerate(errors):
        stats.add(FramePose(k, 1.0 + dx_m, 2.0, 0.5 + dh_rad), FramePose(k, 1.0, 2.0, 0.5))
    return stats


def test_a_jump_of_the_loop_judges_a_correct_firmware_pass() -> None:
    """The real-time loop skips releases when it falls a period behind: here 17 at once. Each
    robot sends the skipped releases' encoder samples late, each at its own release
    (``Fleet.step``): 17 frames back to back, COUNTER +1 each, which the firmware takes as a
    backlog of 10 ms steps and the reference steps alike. The verdict is PASS (before the samples
    were sent, one step held 18 periods of motion: the fleet left the robots UNJUDGED, as steps
    over several cycles moved a correct firmware's position a few LSB off the reference)."""
    from odocan.host.mqtt.telemetry import RobotTelemetry

    profile = robot.load("pmir")
    with Fleet(FleetConfig(robots=2, robot=profile, seed=7)) as fleet:
        telemetry = [RobotTelemetry(name, Geometry.of(profile), "exact",
                                    counter_bits=profile.counter_bits) for name in fleet.names]
        for k in [*range(100), *range(117, 217)]:
            fleet.step(k)
            for i, frame in fleet.take_batch():
                telemetry[i].feed_frame(frame)
        # one encoder frame per release, the 17 skipped ones' too (robot002 a tick out of phase)
        assert [fleet.frame_counts(i)["WHEEL_ENCODERS"] for i in range(2)] == [217, 216]
    trackers = [t.tracker for t in telemetry]
    assert max(t.vs_reference.max_dheading_rad for t in trackers) <= HEADING_LSB_RAD
    for tracker in trackers:
        verdict = judge_robot(tracker.vs_reference, tracker.vs_truth,
                              beyond_allowance_m=tracker.max_beyond_allowance_m)
        assert verdict["verdict"] == "PASS", verdict["reason"]


def test_judge_robot_passes_within_one_lsb_and_fails_beyond_it() -> None:
    """The live judge's rule (``livefit.pose_wrong``): one LSB of position beyond the loss
    allowance, one LSB of heading."""
    truth = _stats((0.05, 0.01))  # odometry drift vs truth: reported, never judged
    ok = judge_robot(_stats((0.5e-4, 1e-5), (-0.9e-4, 0.0)), truth)
    assert ok["verdict"] == "PASS"
    assert ok["reason"] is None
    assert ok["pose_vs_reference"]["samples"] == 2
    assert math.isclose(ok["pose_vs_reference"]["max_dpos_m"], 0.9e-4)
    assert math.isclose(ok["pose_vs_truth"]["max_dpos_m"], 0.05)
    far = judge_robot(_stats((1e-4, 0.0), (1.5e-4, 0.0)), truth)
    assert far["verdict"] == "FAIL"
    assert "position vs reference 0.15 mm (beyond the loss allowance) > 0.1 mm" in far["reason"]
    allowed = judge_robot(_stats((1.5e-4, 0.0)), truth, beyond_allowance_m=0.5e-4)
    assert allowed["verdict"] == "PASS"  # 0.1 mm of it allowed for encoder frames lost
    assert allowed["max_dpos_beyond_allowance_m"] == 0.5e-4
    turned = judge_robot(_stats((0.0, 1.5 * HEADING_LSB_RAD)), truth)
    assert turned["verdict"] == "FAIL"
    assert "heading vs reference 0.1438 mrad > 0.09587 mrad" in turned["reason"]
    silent = judge_robot(ErrorStats(), ErrorStats())
    assert silent["verdict"] == "FAIL"
    assert "no on-board pose" in silent["reason"]
    assert silent["pose_vs_reference"] is None
    assert silent["pose_vs_truth"] is None
    blind = judge_robot(_stats((3e-4, 0.0)), truth, frames_dropped=7)
    assert blind["verdict"] == "UNJUDGED"
    assert "dropped 7 frames" in blind["reason"]


def _worker(first: int, ratio: float, verdicts: list[str]) -> dict[str, object]:
    robots = {f"robot{first + i + 1:03d}": {"verdict": v, "reason": f"why {first + i}"}
              for i, v in enumerate(verdicts)}
    return {"robots": len(verdicts), "first_robot": next(iter(robots)), "duration_s": 1.0,
            "period_s": 0.01, "deadline_miss_ratio": ratio, "ticks": 100,
            "late_ticks": round(ratio * 100), "skipped_releases": 1, "max_lateness_ms": ratio * 50,
            "cpu_s": 0.25,
            "broker": "mqtt://127.0.0.1:1", "embedded_broker": False, "tolerance": {},
            "bridge": {"frames_in": 10, "frames_dropped": 0}, "per_robot": robots}


def test_aggregate_takes_the_worst_worker_and_failures_name_every_threshold() -> None:
    report = aggregate([_worker(0, 0.0, ["PASS", "PASS"]), _worker(2, 0.03, ["PASS", "FAIL"])])
    assert report["robots"] == 4
    assert list(report["per_robot"]) == [
        "robot001", "robot002", "robot003", "robot004"]
    assert report["deadline_miss_ratio"] == 0.03  # not the 0.015 average: a late worker shows
    assert report["ticks"] == 200
    assert report["late_ticks"] == 3
    assert report["cpu_s"] == 0.5
    assert report["skipped_releases"] == 2
    assert report["bridge"]["frames_in"] == 20
    assert [w["first_robot"] for w in report["workers"]] == ["robot001", "robot003"]
    assert failures(report, 0.05) == [
        "1 of 4 robots failed their verdict (robot004: why 3)"]
    assert failures(report, 0.001)[0] == "deadline_miss_ratio 0.0300 > --max-miss-ratio 0.001"
    passing = aggregate([_worker(0, 0.0, ["PASS"]), _worker(1, 0.0, ["PASS"])])
    assert failures(passing, 0.001) == []


def test_fleet_on_two_workers_reports_every_robot(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    report = tmp_path / "fleet.json"
    port = free_loopback_port()
    with embedded_broker(port) as url:  # the shared broker the shards of one fleet meet on
        code = main(["fleet", "-n", "4", "--shard", "2/2", "--workers", "2", "--duration",
                     "2", "--seed", "5", "--broker", str(url), "--max-miss-ratio", "1",
                     "--report", str(report)])
    out, err = capsys.readouterr()
    assert f"fleet: 2 robots running, telemetry on mqtt://127.0.0.1:{port}" in err
    lines = out.splitlines()
    assert lines[0].startswith("fleet: 2 robots, robot003..robot004, 2 worker(s), ")
    data = json.loads(report.read_text())
    # a loaded machine's skipped releases too: their samples are sent late (sim.fleet)
    assert code == 0, out + err
    assert lines[1:] == ["poses: 2 PASS", "PASS"]
    assert data["broker"] == f"mqtt://127.0.0.1:{port}"
    assert [w["first_robot"] for w in data["workers"]] == ["robot003", "robot004"]
    robots = data["per_robot"]
    assert list(robots) == ["robot003", "robot004"]
    assert [r["seed"] for r in robots.values()] == [7, 8]
    for r in robots.values():
        assert r["verdict"] == "PASS", r["reason"]
        assert r["pose_vs_reference"]["max_dheading_rad"] <= 2 * HEADING_LSB_RAD
        assert r["pose_vs_reference"]["samples"] > 20
        assert r["max_dpos_beyond_allowance_m"] <= 2 * POSITION_LSB_M
        assert r["pose_vs_truth"]["samples"] > 0
        assert 0.0 <= r["deadline_miss_ratio"] <= 1.0


class _NeverLate:
    """``sim.fleet.run_realtime``'s clock, never late: its two reads of tick k (the delay
    before the release, the lateness after) both say ``k * TICK_S`` (as bench/fleet_flat.py's did),
    so no release is skipped however loaded the machine."""

    def __init__(self) -> None:
        self.reads = 0

    def now_s(self) -> float:
        self.reads += 1
        return (self.reads - 1) // 2 * TICK_S


def test_a_wrong_pose_fails_the_run_and_says_why(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The judge's reference on a 2 % longer wheelbase than the firmware's: every robot's
    heading departs, the exit line says FAIL and which threshold. The fleet runs on a clock that
    is never late (``_NeverLate``): the summary's tick count is exact."""
    monkeypatch.setattr(sim_fleet, "RealTimeClock", _NeverLate)
    real = fleetrun._endpoints

    def skewed(fleet: Fleet, run: fleetrun.FleetRun) -> list[RobotEndpoint]:
        g = Geometry.of(run.fleet.robot)
        wrong = replace(g, wheelbase_m=g.wheelbase_m * 1.02)
        return [replace(e, geometry=wrong) for e in real(fleet, run)]

    monkeypatch.setattr(fleetrun, "_endpoints", skewed)
    code = main(["fleet", "-n", "2", "--duration", "2", "--scenario", "random",
                 "--max-miss-ratio", "1"])
    out = capsys.readouterr().out.splitlines()
    assert code == 1
    assert "200 ticks, deadline_miss_ratio 0.0000 " in out[0], out[0]  # none skipped
    assert out[1] == "poses: 2 FAIL"
    assert out[2].startswith("FAIL: 2 of 2 robots failed their verdict (robot001:")


def test_a_port_in_use_is_one_error_line(capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as busy:
        busy.bind((LOOPBACK, 0))
        busy.listen()
        port = busy.getsockname()[1]
        code = main(["fleet", "-n", "2", "--port", str(port), "--duration", "1"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith(f"error: --port {port}: 127.0.0.1:{port} cannot be used")
    assert len(err.splitlines()) == 1


def test_sigterm_stops_every_worker_and_the_report_is_written(tmp_path: Path) -> None:
    report = tmp_path / "fleet.json"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "odocan", "fleet", "-n", "3", "--workers", "2", "--duration",
         "120", "--max-miss-ratio", "1", "--report", str(report)],
        cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stderr is not None
    start = proc.stderr.readline()
    assert start.startswith("fleet: 3 robots running, telemetry on mqtt://127.0.0.1:"), start
    wait_until_judged(proc, start, ["robot001", "robot002", "robot003"])  # was a fixed 1 s
    began = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=60)
    assert time.monotonic() - began < 60
    data = json.loads(report.read_text())
    assert proc.returncode == 143, err  # stopped before its 120 s: never 0
    last = out.splitlines()[-1]
    assert last.startswith("STOPPED by SIGTERM at "), last
    assert last.endswith(": partial run PASS"), last  # skipped releases too (sent late)
    assert data["stopped"]["signal"] == "SIGTERM"
    assert list(data["per_robot"]) == ["robot001", "robot002", "robot003"]
    assert len(data["workers"]) == 2
    assert 0 < data["ticks"] < 2 * 120 * 100


def test_run_sharded_passes_on_the_workers_progress() -> None:
    """Two spawned workers without a bridge: progress sums both workers' ticks as they run."""
    from odocan.host.mqtt.fleetrun import FleetRun
    from odocan.host.mqtt.shards import run_sharded

    seen: list[tuple[int, int]] = []
    run = FleetRun(fleet=FleetConfig(robots=3, robot=robot.load("pmir"), seed=2),
                   duration_s=2.0, bridge=False)
    report = run_sharded(run, 2, on_progress=lambda ticks, late: seen.append((ticks, late)))
    assert [w["robots"] for w in report["workers"]] == [1, 2]
    assert len(seen) >= 2
    assert all(0 <= late <= ticks for ticks, late in seen)
    assert [t for t, _ in seen] == sorted(t for t, _ in seen)
    assert seen[-1][0] <= report["ticks"]
    assert all(r["verdict"] is None for r in report["per_robot"].values())  # nothing watched
    assert report["cpu_s"] > 0.0


def _children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (from /proc)."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


def test_workers_and_broker_stop_when_the_parent_is_killed(tmp_path: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "odocan", "fleet", "-n", "2", "--workers", "2", "--duration",
         "300", "--max-miss-ratio", "1"],
        cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    assert proc.stderr is not None
    assert proc.stderr.readline().startswith("fleet: 2 robots running")
    children = _children(proc.pid)
    assert len(children) >= 3  # the broker and two workers (and the spawn resource tracker)
    proc.kill()
    proc.wait()
    deadline = time.monotonic() + 30
    alive = children
    while alive and time.monotonic() < deadline:
        time.sleep(0.5)
        alive = [pid for pid in alive if _running(pid)]
    assert alive == [], alive


def _running(pid: int) -> bool:
    """Process ``pid`` exists and is not a zombie."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def test_a_workers_broker_error_is_one_line_in_the_parent(
    capsys: pytest.CaptureFixture[str],
) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as closed:
        closed.bind((LOOPBACK, 0))  # bound, never listening: connections are refused
        port = closed.getsockname()[1]
        code = main(["fleet", "-n", "2", "--workers", "2", "--broker",
                     f"mqtt://127.0.0.1:{port}", "--duration", "1", "--connect-timeout", "2"])
    err = capsys.readouterr().err
    assert code == 2
    assert err == f"error: cannot connect to mqtt://127.0.0.1:{port}: connection refused\n"


def test_run_sharded_without_a_broker_shares_one_broker_process() -> None:
    from odocan.host.mqtt.fleetrun import FleetRun
    from odocan.host.mqtt.shards import run_sharded

    run = FleetRun(fleet=FleetConfig(robots=2, robot=robot.load("pmir")), duration_s=1.0)
    report = run_sharded(run, 2)
    assert report["embedded_broker"]
    assert report["broker"].startswith("mqtt://127.0.0.1:")
    assert report["bridge"]["frames_in"] > 0
    assert report["bridge"]["reconnects"] == 0
    assert all(r["verdict"] in ("PASS", "UNJUDGED") for r in report["per_robot"].values())
