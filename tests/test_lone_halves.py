"""Lone pose halves (issue #11, rule 5): an ODOM_POSE_X (X, HEADING) or ODOM_POSE_Y (Y, TURNS)
whose partner naming the same encoder frame was lost on the bus was dropped unsaid by every
judge: a lone X raised 10 m PASSed ``analyze`` whole and streamed and left the monitor and the
bridge OK, the summary saying "judged 316 of 316 (100 %)" (kobuki random seed 5, 8 s, drop=0.1:
38 X frames without their Y). Now each is judged on what it carries (``host.judge.lonehalves``,
``host.judge.livelone``), or counted as sent and not judged. Which frames are lone is told here
independently of odocan (cantools, python-can: no ODOM_POSE_Y of the same ENC_COUNTER within
5 ms of an ODOM_POSE_X, and the other way round); the logs are edited with cantools' CRC
(``tests/log_edit.py``)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import can
import cantools
import pytest
from cantools.database.can import Database

from odocan.sim import contract
from tests.log_edit import drop_frames, raise_raw_once
from tests.test_live_reboot import bridge_of, monitor_of

LSB_M = 1e-4  # X, Y: 0.1 mm (dbc/odocan.dbc)
VALUE_BYTES = (2, 4)  # X of ODOM_POSE_X, Y of ODOM_POSE_Y: bytes 2..5, signed little-endian
HEADING_BYTES = (6, 2)  # HEADING of ODOM_POSE_X: bytes 6..7 (u16, raised below its wrap)
LONE_X_S, LONE_Y_S = 0.801, 1.301  # a lone X and a lone Y of the drop=0.1 log (checked below)


def _odocan(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "odocan", *args], capture_output=True,
                          text=True, check=False)


def _run(path: Path, robot: str, seed: int, faults: str) -> Path:
    done = _odocan("run", "--robot", robot, "--scenario", "random", "--seed", str(seed),
                   "--duration", "8", "--faults", faults, "--log", str(path))
    assert path.exists(), done.stderr
    return path


@pytest.fixture(scope="module")
def dropped(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _run(tmp_path_factory.mktemp("lone") / "drop.log", "kobuki", 5, "drop=0.1")


def lone_halves(path: Path) -> tuple[list[float], list[float]]:
    """The times (s after the first frame) of the ODOM_POSE_X frames without an ODOM_POSE_Y of
    the same ENC_COUNTER within 5 ms, and of the Y frames without such an X."""
    db = cantools.database.load_file(str(contract.DBC_PATH))
    assert isinstance(db, Database)
    ids = {db.get_message_by_name(n).frame_id: n for n in ("ODOM_POSE_X", "ODOM_POSE_Y")}
    frames: dict[str, list[tuple[float, int]]] = {"ODOM_POSE_X": [], "ODOM_POSE_Y": []}
    first = None
    for msg in can.LogReader(str(path)):
        first = msg.timestamp if first is None else first
        if msg.arbitration_id in ids:
            frames[ids[msg.arbitration_id]].append((msg.timestamp - first, msg.data[1] >> 4))

    def alone(mine: list[tuple[float, int]], other: list[tuple[float, int]]) -> list[float]:
        return [round(t, 4) for t, e in mine
                if not any(abs(t - u) < 0.005 and e == f for u, f in other)]

    return (alone(frames["ODOM_POSE_X"], frames["ODOM_POSE_Y"]),
            alone(frames["ODOM_POSE_Y"], frames["ODOM_POSE_X"]))


def _analyzed(path: Path, stream: str, robot: str = "kobuki"
              ) -> tuple[int, dict[str, Any], tuple[int, int]]:
    """Exit code, JSON report and the summary's "judged N of M" of ``analyze``."""
    report = path.with_suffix(f".{stream}.json")
    done = _odocan("analyze", "--robot", robot, "--stream", stream, str(path), "--report",
                   str(report))
    assert done.returncode in (0, 1), done.stderr
    judged = re.search(r"judged\s+(\d+) of (\d+) on-board poses", done.stdout)
    assert judged is not None, done.stdout
    return done.returncode, json.loads(report.read_text()), (int(judged[1]), int(judged[2]))


def _live_wrongs(path: Path, robot: str, integrator: str) -> list[tuple[int, float]]:
    """Per live judge (monitor, bridge): POSE WRONG episodes latched and the largest position
    error vs reference (m), after the end of the log."""
    out = []
    for judge in (monitor_of(path, robot, integrator), bridge_of(path, robot, integrator)):
        tracker = judge.tracker
        tracker.wrongs.finish(tracker.allowance_m)
        out.append((tracker.wrongs.count, tracker.vs_reference.max_dpos_m))
    return out


def test_the_log_has_the_lone_halves_edited(dropped: Path) -> None:
    lone_x, lone_y = lone_halves(dropped)
    assert len(lone_x) >= 20
    assert len(lone_y) >= 20
    assert LONE_X_S in lone_x
    assert LONE_Y_S in lone_y


@pytest.mark.parametrize(("message", "at_s", "lsb"), [
    ("ODOM_POSE_X", LONE_X_S, -100_000),  # 10 m
    ("ODOM_POSE_Y", LONE_Y_S, 100_000),
    ("ODOM_POSE_X", LONE_X_S, 100),  # 10 mm
    ("ODOM_POSE_Y", LONE_Y_S, -100),
])
def test_a_wrong_lone_half_fails_whole_streamed_and_live(
    dropped: Path, tmp_path: Path, message: str, at_s: float, lsb: int
) -> None:
    """The one lone half edited: FAIL whole and streamed (the stream reads it whole), POSE
    WRONG in the monitor and the bridge, each error the edit's within a pose's rounding."""
    edited = tmp_path / "edited.log"
    assert raise_raw_once(dropped, edited, message, VALUE_BYTES, lsb, at_s - 0.0005) == [
        pytest.approx(at_s, abs=1e-6)]
    for stream in ("never", "always"):
        code, report, _ = _analyzed(edited, stream)
        assert code == 1, stream
        assert report["passed"] is False
        beyond = report["onboard_vs_reference"]["max_position_error_beyond_allowance_m"]
        assert beyond == pytest.approx(abs(lsb) * LSB_M, abs=LSB_M)
    for wrongs, max_dpos_m in _live_wrongs(edited, "kobuki", "exact"):
        assert wrongs >= 1
        assert max_dpos_m == pytest.approx(abs(lsb) * LSB_M, abs=LSB_M)


def test_the_untouched_log_passes_everywhere_and_counts_its_lone_halves(dropped: Path) -> None:
    """The control: a correct firmware PASSes whole and streamed, no POSE WRONG live (within one
    LSB); the judged line counts the lone halves as sent (it said 316 of 316: none of 74)."""
    lone_x, lone_y = lone_halves(dropped)
    for stream in ("never", "always"):
        code, report, (judged, sent) = _analyzed(dropped, stream)
        assert code == 0, stream
        assert report["passed"] is True
        samples = report["samples"]
        lone = samples["lone_halves_judged"] + samples["lone_halves_unjudged"]
        assert lone >= 0.9 * (len(lone_x) + len(lone_y))  # a few name no encoder frame
        assert sent == samples["onboard"] + lone
        assert judged == samples["onboard"] + samples["lone_halves_judged"]
    for wrongs, max_dpos_m in _live_wrongs(dropped, "kobuki", "exact"):
        assert wrongs == 0
        assert max_dpos_m <= LSB_M


def test_lone_halves_left_unjudged_are_counted_not_hidden(tmp_path: Path) -> None:
    """pmir seed 3, delay=0.3:55: "judged 67 of 67 (100 %)" while 153 X frames were accepted.
    The lone halves are in the judged line now, those it cannot tell as not judged; the correct
    firmware still PASSes."""
    path = _run(tmp_path / "pmir_delay.log", "pmir", 3, "delay=0.3:55")
    code, report, (judged, sent) = _analyzed(path, "never", "pmir")
    assert code == 0
    samples = report["samples"]
    assert samples["lone_halves_judged"] + samples["lone_halves_unjudged"] >= 100
    assert sent == samples["onboard"] + samples["lone_halves_judged"] + samples[
        "lone_halves_unjudged"] + samples["stall_first_judged"] + samples["stall_first_unjudged"]
    assert judged < sent or samples["lone_halves_unjudged"] == 0


def test_a_stalls_first_pose_without_its_y_is_judged_by_the_poses_around_it(
    tmp_path: Path
) -> None:
    """A stall (kobuki seed 5, stall=4:0.2) whose first pose lost its ODOM_POSE_Y: the X half
    is judged by the poses around it (``stallfirst``), a correct one PASSes everywhere (the live
    judge took it for the last sample's frame before: a false POSE WRONG of 15 mm)."""
    stalled = _run(tmp_path / "stall.log", "kobuki", 5, "stall=4:0.2")
    path = tmp_path / "stall_lone.log"
    assert drop_frames(stalled, path, ("ODOM_POSE_Y",), 4.2, 4.205) == 1
    assert 4.201 in lone_halves(path)[0]
    code, report, (judged, sent) = _analyzed(path, "never")
    assert code == 0
    # the lone first and the backlog's next pose, unresolved too (host.judge.stallnext)
    assert report["samples"]["stall_first_judged"] == 2
    assert judged == sent
    for wrongs, max_dpos_m in _live_wrongs(path, "kobuki", "exact"):
        assert wrongs == 0
        assert max_dpos_m <= LSB_M


@pytest.mark.parametrize("lsb", [-100_000, 100])  # X 10 m, 10 mm
def test_a_wrong_lone_first_pose_after_a_stall_on_a_lossy_bus_fails(tmp_path: Path,
                                                                    lsb: int) -> None:
    """A stall's first pose whose Y was lost on a lossy bus (kobuki seed 5,
    stall=4:0.2,drop=0.05): the logger missed frames of the silence too, so neither stallfirst
    nor the reference can tell which frame the X at 4.201 s names; it was counted not judged
    (387 of 388) and a 10 m X PASSed. Judged against every frame it may name (``candidates``):
    the untouched log PASSes with every pose judged, the edit FAILs by it, whole and streamed."""
    stalled = _run(tmp_path / "stall_drop.log", "kobuki", 5, "stall=4:0.2,drop=0.05")
    assert 4.201 in lone_halves(stalled)[0]
    code, _, (judged, sent) = _analyzed(stalled, "never")
    assert (code, judged) == (0, sent)
    edited = tmp_path / "stall_drop_x.log"
    raise_raw_once(stalled, edited, "ODOM_POSE_X", VALUE_BYTES, lsb, 4.2005)
    for stream in ("never", "always"):
        code, report, _ = _analyzed(edited, stream)
        assert code == 1, stream
        beyond = report["onboard_vs_reference"]["max_position_error_beyond_allowance_m"]
        assert beyond > 0.9 * abs(lsb) * LSB_M - 1e-3  # the edit's, less the merge slack


@pytest.mark.xfail(strict=True, reason=(
    "the live judges leave a stall's first lone X unjudged (livelone: sent 0.22 s after the "
    "last sample, past QUIET_S, and a placement due): kobuki seed 5, stall=4:0.2,drop=0.05, "
    "the X at 4.201 s raised 10 m leaves the monitor and the bridge OK (0 POSE WRONG, "
    "largest error 0.071 mm) where analyze FAILs it "
    "9999.9 mm by its candidates (host.judge.candidates); the live judge would have to hold "
    "the half until the sample after it to carry that one back"))
def test_the_live_judges_flag_a_wrong_lone_first_pose_after_a_stall(tmp_path: Path) -> None:
    stalled = _run(tmp_path / "stall_drop.log", "kobuki", 5, "stall=4:0.2,drop=0.05")
    edited = tmp_path / "stall_drop_x.log"
    raise_raw_once(stalled, edited, "ODOM_POSE_X", VALUE_BYTES, -100_000, 4.2005)
    for wrongs, _ in _live_wrongs(edited, "kobuki", "exact"):
        assert wrongs >= 1


@pytest.mark.parametrize(("message", "at_s", "span", "lsb"), [
    ("ODOM_POSE_X", LONE_X_S, VALUE_BYTES, -100_000),  # X 10 m
    ("ODOM_POSE_Y", LONE_Y_S, VALUE_BYTES, 100),  # Y 10 mm
    ("ODOM_POSE_X", LONE_X_S, HEADING_BYTES, 200),  # HEADING 19.2 mrad
])
def test_replay_flags_a_wrong_lone_half_of_the_log(dropped: Path, tmp_path: Path, message: str,
                                                   at_s: float, span: tuple[int, int],
                                                   lsb: int) -> None:
    """Replay compared the logged poses with the replayed firmware's only at frames both halves
    name: the lone X raised 10 m at 0.801 s was one of 35 'unpaired' X not compared (316 of 357
    compared, all identical) and replay PASSed. Each lone half is compared on what it carries
    now (``replay_lone``): FAIL, exit 1."""
    edited = tmp_path / "edited.log"
    raise_raw_once(dropped, edited, message, span, lsb, at_s - 0.0005)
    done = _odocan("replay", "--robot", "kobuki", str(edited), "--log", str(tmp_path / "r.log"))
    assert done.returncode == 1, done.stdout[-400:]
    assert "FAIL: the replayed firmware departs from the log's" in done.stdout


def test_replay_compares_the_lone_halves_of_a_correct_log(dropped: Path, tmp_path: Path) -> None:
    """The control: the untouched log replays PASS, its lone halves compared (those the
    replayed firmware sent a pose for: all but a few naming no encoder frame) and said."""
    lone_x, lone_y = lone_halves(dropped)
    report = tmp_path / "r.json"
    done = _odocan("replay", "--robot", "kobuki", str(dropped), "--report", str(report))
    assert done.returncode == 0, done.stdout[-400:]
    vs = json.loads(report.read_text())["replay"]["onboard_vs_log"]
    lone = vs["lone_halves"]
    assert lone["x"] + lone["y"] >= 0.9 * (len(lone_x) + len(lone_y))
    assert lone["x"] <= len(lone_x)
    assert lone["y"] <= len(lone_y)
    assert f"{lone['x'] + lone['y']} lone pose halves" in done.stdout
    assert vs["max_position_diff_m"] <= LSB_M
    assert vs["max_heading_diff_rad"] == 0.0
