"""``odocan replay`` must be trusted both ways (rule 5, issue #11 item 4): a correct log replays
PASS whatever its bus lived (late, repeated frames, a reboot, bus-off), and a log whose recorded
pose was changed FAILs, every recorded pose compared.

Found by an outside trial: a log with ``delay=0.3:50`` fed 1235 of its 2000 encoder frames (those
the host's E2E window accepted, not those the firmware took) and FAILed a correct firmware by
0.942 mm; the first two poses after a reboot (E2E COUNTER restarted, refused by the host) were
never compared, so a pose raised 10 m there PASSed ("848 identical"); and the replay printed a
PASS line before its FAIL. Every figure below is read from the log itself (its frames, by
cantools and python-can) or from the command's own report, never hard-coded from a run.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import can
import pytest

from tests.log_edit import raise_raw, raise_raw_once

ENCODERS, POSE_X = 0x100, 0x200
TEN_METRES_LSB = 100_000  # ODOM_POSE_X X: 0.1 mm per LSB
TEN_MM_LSB = 100
LSB_M = 1e-4


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(Path(__file__).resolve().parents[1]), os.environ.get("PYTHONPATH", "")]))
    return subprocess.run([sys.executable, "-m", "odocan", *args], capture_output=True,
                          text=True, env=env, check=False)


def _run(log: Path, robot: str, seed: int, duration: float, faults: str,
         scenario: str | None = "circle") -> None:
    extra = [] if scenario is None else ["--scenario", scenario]
    done = _cli("run", "--robot", robot, "--seed", str(seed), "--duration", str(duration),
                *extra, "--faults", faults, "--log", str(log))
    assert done.returncode == 0, done.stdout[-2000:]  # the run itself is correct


def _replay(log: Path, report: Path) -> tuple[int, str, dict[str, Any]]:
    done = _cli("replay", str(log), "--report", str(report))
    return done.returncode, done.stdout, json.loads(report.read_text())["replay"]


def _frames(log: Path, can_id: int) -> list[can.Message]:
    return [m for m in can.LogReader(str(log)) if m.arbitration_id == can_id]


def _verdict_lines(out: str) -> list[str]:
    return [line for line in out.splitlines()
            if line.split(":", 1)[0] in ("PASS", "FAIL", "UNJUDGED")]


def test_every_encoder_frame_reaches_the_replayed_firmware(tmp_path: Path) -> None:
    """H3: the delayed frames arrive late in the log; the recording firmware's own E2E check
    decided on each of them, so the replay feeds them all where they arrived (1235 of 1999 fed,
    FAIL 0.942 mm, before)."""
    log = tmp_path / "d.log"
    _run(log, "pmir", 20, 20, "delay=0.3:50")
    code, out, section = _replay(log, tmp_path / "r.json")
    assert section["encoder_frames_fed"] == len(_frames(log, ENCODERS)), out
    assert code == 0, out
    assert _verdict_lines(out) == [line for line in out.splitlines() if line.startswith("PASS")]


@pytest.mark.parametrize(("robot", "seed", "faults"), [
    # the frames a bus-off held back (tests/test_busoff_release.py) and the reboot's priming
    # frame: on main 71f6fdbf run FAILed it (DISTANCE 22.6 mm beyond its tolerance) and replay
    # did; PASS since the twenty-ninth pass named a new life's priming frame among every frame
    ("pmir", 1, "delay=0.3:50,busoff=5:1,reboot=12,dup=0.1"),
    ("pmir", 5, "delay=0.3:50,busoff=5:1,reboot=12,dup=0.1"),
    ("kobuki", 4, "delay=0.2:30,dup=0.1"),
])
def test_a_correct_log_with_many_faults_replays_pass(tmp_path: Path, robot: str, seed: int,
                                                     faults: str) -> None:
    """A correct run (its own verdict PASS) replays PASS: pmir seed 1 FAILed its life after the
    reboot by 5827.7 mrad before (the life's span on the replayed bus was found by the replayed
    bus's E2E verdicts, 9 frames early), and 47.2 mrad on main."""
    log = tmp_path / "m.log"
    _run(log, robot, seed, 15, faults)
    code, out, _ = _replay(log, tmp_path / "r.json")
    assert code == 0, out


@pytest.mark.xfail(strict=True, reason="a reboot whose first encoder frame came late (pmir seed "
                   "6, delay=0.3:50,busoff=5:1,reboot=12,dup=0.1): the second life is primed "
                   "one frame late (t=12.01 s), heading 9.49 mrad off (22.05 mrad on main); "
                   "only the first life's prime is fitted (replay_lives.fit_first_prime)")
def test_a_late_first_frame_after_a_reboot_replays_pass(tmp_path: Path) -> None:
    log = tmp_path / "m.log"
    _run(log, "pmir", 6, 15, "delay=0.3:50,busoff=5:1,reboot=12,dup=0.1")
    code, out, _ = _replay(log, tmp_path / "r.json")
    assert code == 0, out


def _reboot_log(tmp_path: Path) -> tuple[Path, float]:
    """kobuki, a reboot at 1 s; the time (from the first frame) of the new life's second pose:
    the second X frame after the reboot's first pose with X 0 (found in the log)."""
    log = tmp_path / "k.log"
    done = _cli("run", "--robot", "kobuki", "--duration", "5", "--faults", "reboot=1",
                "--log", str(log))
    assert done.returncode == 0, done.stdout[-2000:]
    t0 = next(iter(can.LogReader(str(log)))).timestamp
    poses = [m for m in _frames(log, POSE_X) if m.timestamp - t0 > 0.5]
    first = next(k for k, m in enumerate(poses) if int.from_bytes(m.data[2:6], "little") == 0)
    return log, poses[first + 1].timestamp - t0


def test_a_raised_pose_after_a_reboot_fails(tmp_path: Path) -> None:
    """H4: the first two poses of a new life (COUNTER from 0, refused by the host's E2E window)
    are compared too: raised 10 m, re-signed, the replay FAILs (PASS, "848 identical", before);
    the log as recorded replays PASS with every one of its poses compared."""
    log, at_s = _reboot_log(tmp_path)
    code, out, section = _replay(log, tmp_path / "ok.json")
    assert code == 0, out
    pose_times = {round(m.timestamp, 6) for m in _frames(log, POSE_X)}
    assert section["onboard_vs_log"]["samples"] == len(pose_times)  # one pose per frame named
    edited = tmp_path / "edited.log"
    assert raise_raw(log, edited, "ODOM_POSE_X", (2, 4), TEN_METRES_LSB, at_s - 0.005,
                     at_s + 0.005) == 1
    code, out, section = _replay(edited, tmp_path / "bad.json")
    assert code == 1, out
    assert section["onboard_vs_log"]["max_position_diff_raw_m"] == pytest.approx(10.0, abs=1e-3)
    lines = _verdict_lines(out)
    assert lines == ["FAIL: the replayed firmware departs from the log's"], out  # once, no PASS


def test_a_burst_drive_replays_pass(tmp_path: Path) -> None:
    """Found by an outside trial (Dec 5): pmir figure8 seed 7286, 20 s, burst=0.01:12 (run
    PASSes). A burst on the firmware's handle lost its first cycle's frames, the boot summary
    with them; the first summary heard (0.2 s, UPTIME 0, E2E COUNTER 4: its firmware's third
    cycle) was taken for the power-up, the replayed firmware reset there, and the replay
    FAILed the correct firmware by 37.7 mm, 1.92 mm between gaps, 12.66 mrad (131 BAM16, the
    heading of its first 0.2 s), blaming 'the firmware build'. A summary not of the first
    cycle names no power-up (``powerup.holds_first_cycle``, analyze's rule too). The log with
    one pose raised 10 mm, and with every pose from 10.5 s on, FAILs."""
    log = tmp_path / "b.log"
    _run(log, "pmir", 7286, 20, "burst=0.01:12", scenario="figure8")
    code, out, _ = _replay(log, tmp_path / "r.json")
    assert code == 0, out
    for name, edit in (("once", raise_raw_once), ("from", raise_raw)):
        edited = tmp_path / f"{name}.log"
        assert edit(log, edited, "ODOM_POSE_X", (2, 4), TEN_MM_LSB, 10.5)
        code, out, section = _replay(edited, tmp_path / f"{name}.json")
        assert code == 1, out
        assert section["onboard_vs_log"]["max_position_diff_m"] > TEN_MM_LSB * LSB_M / 2


def test_a_stall_then_a_reboot_under_a_mild_delay_replays_pass(tmp_path: Path) -> None:
    """Found by an outside trial (Dec 5): kobuki circle seed 5536, 20 s, the run PASSing, replay
    was UNJUDGED ("life 1 (from t=14.08 s): none of the log's 296 on-board poses could be
    paired"). It passes since the replay feeds each encoder frame at the tick its bus time
    reached the firmware and reads a silence's ends by bus time (``replay_arrival``,
    ``replay_lives._periods_after``)."""
    log = tmp_path / "s.log"
    _run(log, "kobuki", 5536, 20, "delay=0.1:15,reboot=13.68:0.3,stall=12.85:0.05")
    code, out, _ = _replay(log, tmp_path / "r.json")
    assert code == 0, out
