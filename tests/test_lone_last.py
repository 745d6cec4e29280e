"""The last pose frame of a log as a lone half (issue #11, rule "a PASS must never hide a wrong
pose"): a log that ends on an ODOM_POSE_X whose ODOM_POSE_Y was never recorded (cut right after
the X), or on an ODOM_POSE_Y whose X was lost (the X dropped, cut after the Y).

Measured on main (da1f202e), kobuki random seed 5, 8 s, clean and drop=0.1, the last X at
7.981 s raised by 100 m, 1 m and 10 mm (``tests/log_edit.py``, CRC by cantools): ``analyze``
whole and ``--stream always`` FAIL it (beyond the allowance 100.0000 m, 1.0000 m, 10.03 mm), but
the live judges left it unjudged: the monitor and the bridge, their watch ended as
``odocan monitor`` and ``odocan bridge`` end it (``release_held``, ``watchend.end_watch``),
showed 0 POSE WRONG and a largest error of 0.068 mm (clean) / 0.083 mm (drop=0.1) for a pose
100 m off; so did a last whole pose (X and Y) with X raised 100 m. A pose half was settled only
by a later half of its message or by bus time past it, and judged alone only when a later sample
paired: at the end of a watch nothing comes later (``livehalves.HalfPairs.end`` now settles and
judges them). Which frame is lone is told independently of odocan (cantools, python-can:
``test_lone_halves.lone_halves``)."""

from __future__ import annotations

import itertools
from pathlib import Path

import can
import pytest

from odocan.host.judge.watchend import end_watch
from tests.log_edit import raise_raw_once
from tests.sweeps import sample
from tests.test_live_reboot import bridge_of, monitor_of
from tests.test_lone_halves import LSB_M, VALUE_BYTES, _analyzed, _odocan, _run, lone_halves

X_ID, Y_ID = 0x200, 0x201  # ODOM_POSE_X, ODOM_POSE_Y (dbc/odocan.dbc)
DRIVES = [("kobuki", 5, "drop=0.1"), ("kobuki", 5, "none"), ("kobuki", 1, "drop=0.1"),
          ("pmir", 3, "none"), ("pmir", 5, "drop=0.1")]


@pytest.fixture(scope="module", params=DRIVES, ids=lambda d: f"{d[0]}-{d[1]}-{d[2]}")
def drive(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
          ) -> tuple[str, Path]:
    robot, seed, faults = request.param
    path = tmp_path_factory.mktemp("last") / f"{robot}{seed}.log"
    return robot, _run(path, robot, seed, faults) if faults != "none" else _clean(
        path, robot, seed)


def _clean(path: Path, robot: str, seed: int) -> Path:
    """A fault-free 8 s random drive."""
    done = _odocan("run", "--robot", robot, "--scenario", "random", "--seed", str(seed),
                   "--duration", "8", "--log", str(path))
    assert path.exists(), done.stderr
    return path


def cut_on_lone(src: Path, dst: Path, half: str) -> float:
    """``src`` copied to ``dst`` up to its last ODOM_POSE_X ("x": its Y cut off) or its last
    ODOM_POSE_Y ("y": the X of the same ENC_COUNTER heard within 5 ms before it dropped), that
    frame the log's last; its time after the first frame."""
    msgs = list(can.LogReader(str(src)))
    last = max(i for i, m in enumerate(msgs) if m.arbitration_id == (X_ID if half == "x" else Y_ID))
    keep = msgs[:last + 1]
    if half == "y":
        enc = msgs[last].data[1] >> 4
        keep = [m for m in keep if not (m.arbitration_id == X_ID and m.data[1] >> 4 == enc
                                         and 0 <= msgs[last].timestamp - m.timestamp < 0.005)]
    with can.Logger(str(dst)) as out:
        for msg in keep:
            out.on_message_received(msg)
    return msgs[last].timestamp - msgs[0].timestamp


def _cut(drive: tuple[str, Path], tmp_path: Path, half: str) -> tuple[Path, float]:
    path = tmp_path / f"cut_{half}.log"
    at_s = round(cut_on_lone(drive[1], path, half), 4)
    assert at_s in lone_halves(path)[0 if half == "x" else 1]  # the last frame, lone
    return path, at_s


def live_ended(path: Path, robot: str) -> list[tuple[int, float]]:
    """Per live judge (monitor, bridge), its watch ended as the CLI ends it: POSE WRONG
    episodes and the largest position error vs reference (m)."""
    monitor = monitor_of(path, robot, "exact")
    monitor.release_held()
    end_watch(monitor.tracker, monitor.distance)
    bridge = bridge_of(path, robot, "exact")
    bridge.end_watch()
    return [(j.tracker.wrongs.count, j.tracker.vs_reference.max_dpos_m)
            for j in (monitor, bridge)]


@pytest.mark.parametrize(("lsb", "half"),  # 100 m, 1 m, 10 mm; tests.sweeps: 10 mm always
                         sample(itertools.product([1_000_000, -10_000, 100], ["x", "y"]), 2,
                                [(100, "x"), (100, "y")]))
def test_a_wrong_last_lone_half_fails_whole_streamed_and_live(
    drive: tuple[str, Path], tmp_path: Path, half: str, lsb: int
) -> None:
    """The log's last pose frame, lone, raised: FAIL whole and streamed, POSE WRONG in the
    monitor and the bridge once the watch ends, each error the edit's within a pose's rounding
    (main: analyze FAILed, the live judges 0 POSE WRONG, largest error <= 0.09 mm)."""
    robot = drive[0]
    cut, at_s = _cut(drive, tmp_path, half)
    edited = tmp_path / "edited.log"
    message = "ODOM_POSE_X" if half == "x" else "ODOM_POSE_Y"
    assert raise_raw_once(cut, edited, message, VALUE_BYTES, lsb, at_s - 0.0005) == [
        pytest.approx(at_s, abs=1e-6)]
    for stream in ("never", "always"):
        code, report, _ = _analyzed(edited, stream, robot)
        assert code == 1, stream
        beyond = report["onboard_vs_reference"]["max_position_error_beyond_allowance_m"]
        assert beyond == pytest.approx(abs(lsb) * LSB_M, abs=LSB_M)
    for wrongs, max_dpos_m in live_ended(edited, robot):
        assert wrongs >= 1
        assert max_dpos_m == pytest.approx(abs(lsb) * LSB_M, abs=LSB_M)


@pytest.mark.parametrize("half", ["x", "y"])
def test_a_correct_log_cut_on_a_lone_half_passes_everywhere(
    drive: tuple[str, Path], tmp_path: Path, half: str
) -> None:
    """The control: the cut log untouched PASSes whole and streamed, and the
    live judges end their watch without POSE WRONG, within one LSB."""
    robot = drive[0]
    cut, _ = _cut(drive, tmp_path, half)
    for stream in ("never", "always"):
        code, report, _ = _analyzed(cut, stream, robot)
        assert code == 0, stream
        assert report["passed"] is True
    for wrongs, max_dpos_m in live_ended(cut, robot):
        assert wrongs == 0
        assert max_dpos_m <= LSB_M


def test_a_wrong_last_whole_pose_fails_live(tmp_path: Path) -> None:
    """Not lone: a log ending on a whole pose (kobuki seed 5, clean, cut after its last
    ODOM_POSE_Y), its X raised 100 m: analyze FAILed it, the live judges ended OK on main (0
    POSE WRONG, 0.068 mm): its halves were never settled."""
    src = _clean(tmp_path / "k5.log", "kobuki", 5)
    msgs = list(can.LogReader(str(src)))
    last = max(i for i, m in enumerate(msgs) if m.arbitration_id == Y_ID)
    cut = tmp_path / "cut.log"
    with can.Logger(str(cut)) as out:
        for msg in msgs[:last + 1]:
            out.on_message_received(msg)
    lx = max(i for i, m in enumerate(msgs[:last]) if m.arbitration_id == X_ID)
    edited = tmp_path / "edited.log"
    raise_raw_once(cut, edited, "ODOM_POSE_X", VALUE_BYTES, 1_000_000,
                   msgs[lx].timestamp - msgs[0].timestamp - 0.0005)
    code, _, _ = _analyzed(edited, "never")
    assert code == 1
    for wrongs, max_dpos_m in live_ended(edited, "kobuki"):
        assert wrongs >= 1
        assert max_dpos_m == pytest.approx(100.0, abs=LSB_M)
