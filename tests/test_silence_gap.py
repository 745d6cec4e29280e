"""A wrong pose after a long silence of the encoder sender FAILs every judge (issue #11, rule 5).

Found by the outside trial: the motor controller silent for 10 to 30 s (bus-off) while the
firmware went on talking; its ODOM_STATUS pages, heard all through the silence, show it took no
encoder frame there (ENC_E2E_OK unchanged). But ``gapseen`` paired pages only less than 7 s
apart (``WRAP_SAFE_S``: the u16 counts cannot wrap in that time), so the gap kept
``gapbound``'s worst-case allowance (21.78 m after 30 s on a kobuki) and a pose 10 m off after
the silence PASSed ``analyze``, streamed or not, and the live judge. The counts are now chained
page to page (``host.judge.pagechain``): each step less than 7 s is exact, so their sum is exact
however long the silence.

The drives: the lockstep rig (``tests.fault_rig``) with the motor controller muted (its node
runs no tick: no encoder frame, no truth) for 8 to 30 s on a square, a random and a circle
drive; the firmware runs on. The wrong firmwares: the correct one's log with ODOM_POSE_X.X raised
by 1 mm, 100 mm or 10 m from the first pose after the silence (the one the placement after the
gap rests on), re-signed with cantools' Profile 2 CRC. The checker is the test's own: cantools
decodes the log; float64 odometry of every encoder frame (the silence one merged step, as the
firmware took it, or none where it is ambiguous) matches the correct firmware's pose within 2 LSB,
the firmware's pages heard through the silence show ENC_E2E_OK unchanged.

Sampled (``tests.sweeps``): the grid of wrong poses (edit x drive); pinned, each drive and each
edit once, among them the 10 m after the square's 30 s silence (the PASS found).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import cantools
import pytest
from cantools.autosar import compute_profile2_crc
from cantools.database.can import Database

from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import POSITION_LSB_M, analyze
from odocan.sim.board import TICK_S
from odocan.sim.contract import DBC_PATH
from odocan.sim.robot import load
from odocan.sim.scenarios import get_scenario
from tests.dbc_typed import dbc_attribute, decode, number
from tests.fault_rig import FaultRig
from tests.independent_checker import Robot, _Odometry
from tests.sweeps import sample
from tests.test_replay_clock_step import _raise_x
from tests.test_sender_stall_drop import live_judges

ROBOT = "kobuki"
# scenario, seed, drive (s), silence from (s), silence (s)
DRIVES = (("square", 0, 45.0, 5.0, 30.0), ("random", 4, 22.0, 6.0, 8.0),
          ("circle", 0, 28.0, 7.0, 12.0))
EDITS_LSB = (10, 1_000, 100_000)  # 1 mm, 100 mm, 10 m of X
# (edit, scenario) judged: each edit and each drive once, the found 10 m after 30 s among them
EDITED = sample([(lsb, drive[0]) for lsb in EDITS_LSB for drive in DRIVES], 4,
                [(10, "random"), (1_000, "circle"), (100_000, "square")])
EDIT_BEFORE_S = 0.002  # the edit starts with the first pose after the silence (sent 1 ms after
# its tick's encoder frame; the last pose in the silence went out 10 ms before)


def _silent_drive(tmp: Path, scenario: str, seed: int, drive_s: float, from_s: float,
                  silence_s: float) -> Path:
    """The rig's log of a drive whose motor controller is muted from ``from_s`` for
    ``silence_s`` (the firmware runs on)."""
    profile = load(ROBOT)
    heard: list[Any] = []
    muted = range(round(from_s / TICK_S), round((from_s + silence_s) / TICK_S))
    plan = get_scenario(scenario, profile, seed=seed, duration_s=drive_s)
    with FaultRig(robot=ROBOT, scenario=plan, seed=seed) as rig:
        rig.observers.append(lambda _k, frames: heard.extend(frames))
        rig.mute_sim(muted)
        rig.run(drive_s)
    path = tmp / f"{scenario}-{silence_s:g}.log"
    path.write_text("".join(f"({m.timestamp:.6f}) vcan0 {m.arbitration_id:03X}#"
                            f"{m.data.hex().upper()}\n" for m in heard))
    return path


@pytest.fixture(scope="module")
def drives(tmp_path_factory: pytest.TempPathFactory) -> list[tuple[Path, float]]:
    """Per drive, its log and the end of its silence (s)."""
    tmp = tmp_path_factory.mktemp("silence")
    return [(_silent_drive(tmp, *drive), drive[3] + drive[4]) for drive in DRIVES]


@pytest.fixture(scope="module")
def recorder_loss(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The random drive without a silence, its log cut of every encoder frame for 6 s from 7 s
    (a recorder that lost the encoder frames only and spared the firmware's: the firmware took
    them one by one, its pages count them). 6 s: the wheels' 16-bit counts moved less than
    half their range (6 s on the circle: more, the merged step's heading wrong by 24.3 rad, a
    correct firmware FAILs: counters wrapping in a gap are another slice's)."""
    tmp = tmp_path_factory.mktemp("recorderloss")
    path = _silent_drive(tmp, "random", 4, 22.0, 7.0, 0.0)
    cut = tmp / "cut.log"
    cut.write_text("".join(line + "\n" for line in path.read_text().splitlines()
                           if not (line.split()[2].startswith("100#")
                                   and 7.0 <= float(line.split()[0].strip("()")) < 13.0)))
    return cut


def _db() -> Database:
    db = cantools.database.load_file(str(DBC_PATH))
    assert isinstance(db, Database)
    return db


def _checked(path: Path) -> tuple[float, int, set[int]]:
    """The test's own checker: the largest on-board position error (m) against float64
    odometry of every encoder frame (a gap one step, none when it is ambiguous: a gap of
    ``_least_ambiguous_periods`` or more, on which the firmware re-primes), the longest time
    between encoder frames
    (in periods) and the ENC_E2E_OK values of the pages heard inside it."""
    db, profile = _db(), load(ROBOT)
    odo = _Odometry(Robot(profile.counts_per_rev, round(profile.wheel_radius_left_m * 1e9),
                          round(profile.wheel_radius_right_m * 1e9),
                          round(profile.wheelbase_m * 1e9), profile.counter_bits), "exact")
    prev: tuple[float, int, int] | None = None
    by_counter: dict[int, tuple[float, float]] = {}
    x_of: dict[int, float] = {}
    worst, longest, pages = 0.0, (0, 0.0, 0.0), []
    for line in path.read_text().splitlines():
        stamp, _, frame = line.split()[:3]
        t_s = float(stamp.strip("()"))
        can_id, data = (int(frame.split("#")[0], 16), bytes.fromhex(frame.split("#")[1]))
        message = db.get_message_by_frame_id(can_id)
        s: dict[str, Any] = dict(db.decode_message(can_id, data, decode_choices=False,
                                                   scaling=False))  # type: ignore[arg-type]
        if message.name == "WHEEL_ENCODERS":
            if prev is not None:
                periods = round((t_s - prev[0]) / 0.01)
                longest = max(longest, (periods, prev[0], t_s))
            if prev is not None and periods < _least_ambiguous_periods(profile):
                odo.step((s["LEFT_COUNT"] - prev[1] + 32768) % 65536 - 32768,
                         (s["RIGHT_COUNT"] - prev[2] + 32768) % 65536 - 32768)
            prev = (t_s, int(s["LEFT_COUNT"]), int(s["RIGHT_COUNT"]))
            by_counter[int(s["COUNTER"])] = (odo.x, odo.y)
        elif message.name == "ODOM_POSE_X":
            x_of[int(s["ENC_COUNTER"])] = float(s["X"]) * POSITION_LSB_M
        elif message.name == "ODOM_POSE_Y" and int(s["ENC_COUNTER"]) in x_of:
            named = int(s["ENC_COUNTER"])
            want = by_counter[named]
            worst = max(worst, math.hypot(x_of[named] - want[0],
                                          float(s["Y"]) * POSITION_LSB_M - want[1]))
        elif message.name == "ODOM_STATUS" and s.get("PAGE") == 2:
            pages.append((t_s, int(s["ENC_E2E_OK"])))
    inside = {ok for t_s, ok in pages if longest[1] + 0.05 < t_s < longest[2] - 0.05}
    return worst, longest[0], inside


def _least_ambiguous_periods(profile: Any) -> int:
    """The fewest periods whose speed bound reaches half the 16-bit range (float64 here: a
    wheel's most counts a period, ceil(v_max T / travel per count) + 1): a step that long is
    ambiguous, the firmware re-primes on it and integrates nothing (kobuki: 84, 391)."""
    travel_m = 2 * math.pi * min(profile.wheel_radius_left_m, profile.wheel_radius_right_m)
    most = math.ceil(profile.max_wheel_speed_m_s * TICK_S * profile.counts_per_rev / travel_m) + 1
    least: int = math.ceil(32768 / most)
    return least


def _verdicts(path: Path, tmp: Path) -> dict[str, bool]:
    """PASS (True) of the whole-log and the streamed analyze and of the live judges."""
    out = {"whole": analyze(read_log(path), load(ROBOT)).passed,
           "streamed": main(["analyze", str(path), "--robot", ROBOT, "--stream", "always",
                             "--report", str(tmp / "r.json")]) == 0}
    for name, tracker in live_judges(path, ROBOT):  # type: ignore[arg-type]  # a name
        out[name.split()[0]] = tracker.wrongs.count == 0
    return out


def test_the_firmware_took_no_frame_in_the_silence(drives: list[tuple[Path, float]]) -> None:
    """The premise, by the test's own checker: a silence of 8 to 30 s, the firmware's pages
    heard through it with one ENC_E2E_OK, its pose float64 odometry with the silence merged."""
    for path, _ in drives:
        worst_m, periods, inside = _checked(path)
        assert periods >= 800, path
        assert len(inside) == 1, (path, inside)
        assert worst_m < 2.5 * POSITION_LSB_M, (path, worst_m)


def test_the_correct_firmware_passes_every_judge(drives: list[tuple[Path, float]],
                                                 tmp_path: Path) -> None:
    for path, _ in drives:
        verdicts = _verdicts(path, tmp_path)
        assert all(verdicts.values()), (path, verdicts)


def test_a_recorder_loss_of_the_encoder_frames_only_keeps_its_allowance(
        recorder_loss: Path, tmp_path: Path) -> None:
    """The pages heard through a 6 s hole of the log's encoder frames count the frames the
    firmware took there (ENC_E2E_OK grew): no proof, the allowance stays, the correct firmware
    PASSes although its pose did not take the gap as one step. (The judges' ambiguity mirror
    re-primed the reference at the hole, 600 periods, kobuki ambiguous from 391: a FAIL of
    the correct firmware, its heading 10.8 rad off the reference's.)"""
    worst_m, periods, inside = _checked(recorder_loss)
    assert periods >= 600  # ten pages: beyond the pairs of nearby pages (a long pair)
    assert len(inside) >= 8  # ENC_E2E_OK grew through the hole
    assert worst_m > 10 * POSITION_LSB_M  # one merged step is not what the firmware took
    verdicts = _verdicts(recorder_loss, tmp_path)
    assert all(verdicts.values()), verdicts


def _taken_in_silence(src: Path, dst: Path, from_s: float, silence_s: float) -> int:
    """``src`` with ENC_E2E_OK of every ODOM_STATUS page 2 sent after ``from_s`` raised by the
    periods since then (at most the silence's): pages that say the firmware took a frame a
    period all through the silence (LOST unchanged), re-encoded and re-signed by cantools;
    the pages changed."""
    db = _db()
    status = db.get_message_by_name("ODOM_STATUS")
    ids = [int(v) for v in dbc_attribute(status, "E2EDataIDs").split(",")]
    lines, changed = [], 0
    for line in src.read_text().splitlines():
        stamp, channel, frame = line.split()[:3]
        t_s = float(stamp.strip("()"))
        head, payload = frame.split("#")
        data = bytes.fromhex(payload)
        if int(head, 16) == status.frame_id and (data[1] >> 4) == 2 and t_s > from_s:
            s = decode(db, status.frame_id, data, decode_choices=False, scaling=False)
            s["ENC_E2E_OK"] = (int(number(s["ENC_E2E_OK"])) + min(round((t_s - from_s) / TICK_S),
                                                           round(silence_s / TICK_S))) & 0xFFFF
            out = bytearray(db.encode_message(status.frame_id, s, scaling=False))
            out[0] = int(compute_profile2_crc(bytes(out), ids[out[1] & 0xF]) or 0)
            line, changed = f"{stamp} {channel} {head}#{out.hex().upper()}", changed + 1
        lines.append(line + "\n")
    dst.write_text("".join(lines))
    return changed


def test_a_firmware_that_reprimed_where_its_pages_say_it_took_frames_fails(
        drives: list[tuple[Path, float]], tmp_path: Path) -> None:
    """The control of the recorder loss: the random drive's 8 s silence (800 periods, ambiguous
    from 391: the correct firmware re-primed there, no step) with pages that say the firmware
    took a frame every period through it. A firmware that re-primed where it took frames one
    by one dropped the silence's motion: every judge FAILs it (the mirror re-primed with it
    and PASSed it when it re-primed at any hole of the log that long)."""
    path, drive = drives[1][0], DRIVES[1]
    edited = tmp_path / "reprimed-where-taken.log"
    assert _taken_in_silence(path, edited, drive[3], drive[4]) > 20  # a page 2 every 0.6 s
    _, periods, inside = _checked(edited)
    assert periods >= 800
    assert len(inside) >= 10  # OK grew all through the silence
    verdicts = _verdicts(edited, tmp_path)
    assert not any(verdicts.values()), verdicts


@pytest.mark.parametrize("lsb", EDITS_LSB)
def test_a_pose_wrong_after_the_silence_fails_every_judge(
        drives: list[tuple[Path, float]], tmp_path: Path, lsb: int) -> None:
    for (path, end_s), drive in zip(drives, DRIVES, strict=True):
        if (lsb, drive[0]) not in EDITED:
            continue
        edited = tmp_path / f"{path.stem}-{lsb}.log"
        assert _raise_x(path, edited, lsb, end_s - EDIT_BEFORE_S) > 100
        worst_m, _, _ = _checked(edited)
        assert worst_m > 0.9 * lsb * POSITION_LSB_M  # the checker sees it
        verdicts = _verdicts(edited, tmp_path)
        assert not any(verdicts.values()), (edited, verdicts)
