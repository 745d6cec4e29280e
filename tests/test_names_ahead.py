"""A pose frame naming an encoder frame not yet sent is a firmware defect, FAILed by every judge
(issue #11: a PASS must never hide a wrong pose; ``host.judge.namesahead``, ``liveahead``).

An outside trial raised ODOM_POSE_X's X by 10 mm in poses 0-489 of a 10 s square drive and set
the ENC_COUNTER of those poses (X, Y and their ODOM_TWIST) one on, re-signed with cantools: the
judges left every such pose out (the frame named comes after it in the log) and PASSed on the
10 left ("judged 10 of 500"), ``--stream always`` and ``--junit`` alike, and the live monitor
said OK. All 500 so named exited 2, "no ODOM_POSE_X/ODOM_POSE_Y pair names an encoder frame"
(a defect called bad input). The tamper and the check here are the test's own (cantools),
not odocan's decoder."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import can
import cantools
import numpy as np
import pytest
from cantools.autosar import compute_profile2_crc
from cantools.database.can import Database

from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.liveahead import LiveAhead
from odocan.host.judge.namesahead import AheadScan
from odocan.host.mqtt.endverdict import end_verdict
from odocan.host.mqtt.fleetjudge import watched_verdict
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import check_frames
from odocan.sim import contract
from tests.dbc_typed import dbc_attribute
from tests.judges_cli import fails_by_position, live_judges, raise_x_10_mm

NAMING = ("ODOM_POSE_X", "ODOM_POSE_Y", "ODOM_TWIST")  # the frames one firmware tick sends
TEN_MM_LSB = 100
JITTER_S = 1e-3  # the recorder's stamping (io.logs: frames back by 1 ms or less)
LAP_S = 0.155  # 16 encoder periods of 10 ms, less half a period
SENDS_BEFORE = 8  # pose frames of 20 ms over a lap of 16 encoder frames of 10 ms


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The trial's drive: ``odocan run --scenario square --duration 10``, asserted a PASS."""
    log = tmp_path_factory.mktemp("ahead") / "base.log"
    assert main(["run", "--scenario", "square", "--duration", "10", "--log", str(log)]) == 0
    return log


def _db() -> Database:
    db = cantools.database.load_file(str(contract.DBC_PATH))
    assert isinstance(db, Database)
    return db


def name_ahead(src: Path, dst: Path, first: int, last: int, step: int, dx_lsb: int) -> int:
    """The trial's tamper: in the ``first``..``last`` frames (by their order among each
    message's) of ODOM_POSE_X, ODOM_POSE_Y and ODOM_TWIST, ENC_COUNTER + ``step`` (mod 16), X +
    ``dx_lsb``; each re-signed with its Profile 2 CRC by cantools. The X frames changed."""
    db = _db()
    messages = {db.get_message_by_name(n).frame_id: db.get_message_by_name(n) for n in NAMING}
    ids = {k: [int(v) for v in dbc_attribute(m, "E2EDataIDs").split(",")]
           for k, m in messages.items()}
    seen = dict.fromkeys(messages, 0)
    changed = 0
    with can.Logger(str(dst)) as out:
        for msg in can.LogReader(str(src)):
            message = messages.get(msg.arbitration_id)
            if message is not None:
                k, seen[msg.arbitration_id] = seen[msg.arbitration_id], seen[msg.arbitration_id] + 1
                if first <= k <= last:
                    raw = _raw(message.decode(bytes(msg.data), scaling=False,
                                              decode_choices=False))
                    raw["ENC_COUNTER"] = (int(raw["ENC_COUNTER"]) + step) % 16
                    if message.name == "ODOM_POSE_X":
                        raw["X"] = int(raw["X"]) + dx_lsb
                        changed += 1
                    data = bytearray(message.encode(raw, scaling=False))
                    data[0] = compute_profile2_crc(bytes(data), ids[msg.arbitration_id][
                        data[1] & 0xF]) or 0
                    msg.data = data
            out.on_message_received(msg)
    return changed


def named_before_sent(log: Path) -> set[tuple[str, float, float]]:
    """The test's own reading (cantools): each pose frame (message, time) whose ENC_COUNTER
    is that of an encoder frame heard more than ``JITTER_S`` after it, while the latest encoder
    frame of that COUNTER before it was heard a whole COUNTER lap (16 frames of 10 ms) before
    that one: the frame it names was not sent yet (the pose's sender heard over that lap too:
    ``SENDS_BEFORE`` of its frames before it). With the time that frame was heard."""
    db = _db()
    enc_id = db.get_message_by_name("WHEEL_ENCODERS").frame_id
    poses = {db.get_message_by_name(n).frame_id: n for n in NAMING[:2]}
    encoders: list[tuple[float, int]] = []
    waiting: list[tuple[str, float, int, float]] = []  # pose, t, ENC_COUNTER, latest same
    found: set[tuple[str, float, float]] = set()
    sent: dict[int, int] = {}  # frames of each pose message so far
    for msg in can.LogReader(str(log)):
        if msg.arbitration_id == enc_id:
            counter = msg.data[1] & 0xF
            encoders.append((msg.timestamp, counter))
            for pose, t, named, before in waiting:
                if (named == counter and msg.timestamp - t > JITTER_S
                        and msg.timestamp - before >= LAP_S):
                    found.add((pose, round(t, 6), round(msg.timestamp, 6)))
            waiting = [w for w in waiting if msg.timestamp - w[1] < 0.08 and w[2] != counter]
        elif msg.arbitration_id in poses:
            named = int(_raw(db.get_message_by_frame_id(msg.arbitration_id).decode(
                bytes(msg.data), scaling=False, decode_choices=False))["ENC_COUNTER"])
            latest = max((t for t, c in encoders if c == named), default=None)
            sent[msg.arbitration_id] = sent.get(msg.arbitration_id, 0) + 1
            if latest is not None and sent[msg.arbitration_id] > SENDS_BEFORE:
                waiting.append((poses[msg.arbitration_id], msg.timestamp, named, latest))
    return found


def _raw(decoded: object) -> dict[str, Any]:
    """cantools' decoded signals (raw, no choices) as a plain dict."""
    assert isinstance(decoded, dict)
    return dict(decoded)


def _analyze(log: Path, stream: str, work: Path) -> tuple[int, dict[str, Any], str]:
    report, junit = work / f"{stream}.json", work / f"{stream}.xml"
    code = main(["analyze", str(log), "--stream", stream, "--report", str(report),
                 "--junit", str(junit)])
    return code, json.loads(report.read_text()), junit.read_text()


@pytest.mark.parametrize(("first", "last", "step"), [(0, 489, 1), (100, 349, 1), (0, 489, 2),
                                                     (0, 489, 5)])
def test_a_pose_naming_a_frame_not_yet_sent_fails_every_judge(
        drive: Path, tmp_path: Path, first: int, last: int, step: int) -> None:
    """The trial's tamper (and its 100..349, +2, +5 variants): ``analyze`` whole and streamed
    exit 1 naming the first such pose as the test's own reading finds it, ``--junit`` has the
    failure, the monitor says POSE WRONG, the bridge's end verdict and the fleet's FAIL, with
    that reason."""
    tampered = tmp_path / "ahead.log"
    assert name_ahead(drive, tampered, first, last, step, TEN_MM_LSB) == last - first + 1
    truth = named_before_sent(tampered)
    assert len(truth) > 0.9 * 2 * (last - first + 1) - 40, len(truth)  # X and Y, most of them
    earliest = min(truth, key=lambda f: (f[1], f[0]))
    for stream in ("never", "always"):
        code, report, junit = _analyze(tampered, stream, tmp_path)
        ahead = report.get("names_ahead")
        assert (code, report["passed"], bool(ahead)) == (1, False, True), (stream, ahead)
        assert ahead is not None
        said = ahead["first"]
        assert (said["message"], round(said["t_s"], 6), round(said["sent_s"], 6)) == earliest
        assert ahead["frames"] == len(truth), (stream, ahead["frames"], len(truth))
        assert "encoder_named_after_sent" in junit
        assert "<failure" in junit
    monitor, bridge = live_judges("pmir", tampered)
    health = monitor.health(monitor.bus_time_s)
    assert health["state"] == "POSE WRONG", health["why"]
    assert f"{earliest[0]} at {earliest[1]:.6f} s names WHEEL_ENCODERS" in health["why"][0]
    bridge.end_watch()
    verdict = end_verdict(bridge)
    assert verdict.verdict == "FAIL", verdict
    assert "not sent until" in verdict.reason, verdict
    fleet = watched_verdict(bridge, 0, None)  # the fleet's verdict of a bridged robot
    assert fleet["verdict"] == "FAIL", fleet
    assert "not sent until" in fleet["reason"], fleet


def test_every_pose_naming_ahead_is_a_fail_not_bad_input(
        drive: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """All 500 poses named one on: no pose pairs with its frame, and the exit is 1 with the
    defect named (it was 2, "no ODOM_POSE_X/ODOM_POSE_Y pair names an encoder frame")."""
    tampered = tmp_path / "all.log"
    name_ahead(drive, tampered, 0, 10_000, 1, 0)
    for stream in ("never", "always"):
        capsys.readouterr()
        assert main(["analyze", str(tampered), "--stream", stream]) == 1
        err = capsys.readouterr().err  # (streamed: a note first, such a log is read whole)
        assert err.splitlines()[-1].startswith("FAIL: ODOM_POSE_X at "), err
        assert "not sent until" in err, err


def test_the_correct_drive_passes_and_no_judge_finds_a_name_ahead(drive: Path,
                                                                  tmp_path: Path) -> None:
    """The untampered drive: every judge passes it and none finds a pose named ahead (the
    test's own reading finds none either)."""
    assert named_before_sent(drive) == set()
    for stream in ("never", "always"):
        code, report, _ = _analyze(drive, stream, tmp_path)
        assert code == 0
        assert "names_ahead" not in report
    monitor, bridge = live_judges("pmir", drive)
    assert monitor.health(monitor.bus_time_s)["state"] == "OK"
    bridge.end_watch()
    assert end_verdict(bridge).verdict == "PASS"
    assert bridge.ahead.count == 0


@pytest.mark.parametrize("chunk", [1, 37, 1000])
def test_the_live_rule_and_the_scan_find_the_same_frames(drive: Path, tmp_path: Path,
                                                         chunk: int) -> None:
    """``LiveAhead`` frame by frame and ``AheadScan`` whole or in chunks: the same count and
    the same earliest findings, on the tampered and the correct drive."""
    tampered = tmp_path / "ahead.log"
    name_ahead(drive, tampered, 100, 349, 1, TEN_MM_LSB)
    for log in (drive, tampered):
        frames, db = read_log(log), default_plan()
        accepted = check_frames(frames, db)[1]
        scan = AheadScan(BulkDecoder(db))
        for lo in range(0, len(frames), chunk):
            at = np.arange(lo, min(lo + chunk, len(frames)))
            scan.feed(frames.select(at), accepted[at])
        live = LiveAhead(db)
        by_id = {m.frame_id: m for m in db.messages}
        for k in range(len(frames)):
            message = by_id.get(int(frames.can_id[k]))
            if message is not None and int(frames.dlc[k]) == message.length:
                live.heard(message.name, float(frames.timestamp_s[k]),
                           bytes(frames.data[k][:message.length]), bool(accepted[k]))
        assert (scan.count, scan.found) == (live.count, live.found)


def written_before_encoders(src: Path, dst: Path) -> int:
    """A recorder's reorder (the trial's swap.log): each run of ODOM_POSE_X, ODOM_POSE_Y,
    ODOM_TWIST lines moved before the WHEEL_ENCODERS line they name, nearest before them (the
    pose stamped 1 ms after it); stamps kept. The runs moved."""
    db = _db()
    enc_id = db.get_message_by_name("WHEEL_ENCODERS").frame_id
    tick = {db.get_message_by_name(n).frame_id for n in NAMING}
    lines = src.read_text().splitlines(keepends=True)
    ids = [int(line.split()[2].split("#")[0], 16) for line in lines]
    out: list[str] = []
    moved, k = 0, 0
    while k < len(lines):
        end = k
        while end < len(lines) and ids[end] in tick:
            end += 1
        enc = max((j for j in range(len(out) - 1, max(len(out) - 8, -1), -1)
                   if int(out[j].split()[2].split("#")[0], 16) == enc_id), default=None)
        if end > k and enc is not None:
            out[enc:enc] = lines[k:end]
            moved, k = moved + 1, end
        else:
            out.append(lines[k])
            k += 1
    dst.write_text("".join(out))
    assert sorted(out) == sorted(lines)
    return moved


@pytest.mark.xfail(strict=True, reason="analyze exits 2 'no ODOM_POSE_X/ODOM_POSE_Y pair names "
                   "an encoder frame' (0 of 500 poses judged): samples.match_encoder pairs a pose "
                   "only with an encoder frame before it in the log. Pairing the reordered ones "
                   "(namesahead's 'reordered': the frame heard <= 1 ms after the pose) in the "
                   "whole log's judge was built (this drive: PASS, 492 of 500 judged; X +10 mm "
                   "still FAILs) and reverted: StreamPoses resolves causally chunk by chunk and "
                   "left tests/test_stream.py's awkward log's poses 150/152/161 out, so the two "
                   "judges' samples differed (14 stream-equality tests); it needs StreamPoses "
                   "and the live tracker to hold a forward-named pose for its frame")
def test_a_recorders_reorder_within_its_jitter_pairs_and_passes(drive: Path,
                                                                tmp_path: Path) -> None:
    """Pose lines written ~1 ms before their encoder line (stamps after it: a recorder's order,
    within the 1 ms stamping the log reader tolerates) pair with it: ``analyze`` PASSes (it
    exited 2, "no ODOM_POSE_X/ODOM_POSE_Y pair names an encoder frame"), judging most poses;
    and X raised 10 mm from 5 s on still FAILs by the position."""
    swapped = tmp_path / "swap.log"
    assert written_before_encoders(drive, swapped) > 450
    assert named_before_sent(swapped) == set()  # within the jitter: nothing named ahead
    for stream in ("never", "always"):
        code, report, _ = _analyze(swapped, stream, tmp_path)
        assert code == 0, stream
        assert "names_ahead" not in report
        assert report["samples"]["onboard"] > 450, report["samples"]
    tampered = tmp_path / "swap_x.log"
    assert raise_x_10_mm(swapped, tampered, 5.0) > 200
    assert fails_by_position(tampered, tmp_path) == []


@pytest.mark.xfail(strict=True, reason="the live judges pair a pose only with an encoder frame "
                   "heard before it: on the reordered drive (every pose line 1 ms before its "
                   "encoder line) the monitor compares none, UNVERIFIED 'no on-board pose "
                   "compared with the reference yet' (no false PASS nor FAIL); pairing a pose "
                   "with a frame heard after it needs the live tracker to hold it for that frame")
def test_the_live_judges_pair_a_recorders_reorder_too(drive: Path, tmp_path: Path) -> None:
    """The monitor on the reordered drive: OK, as on the drive as recorded."""
    swapped = tmp_path / "swap.log"
    written_before_encoders(drive, swapped)
    monitor, _ = live_judges("pmir", swapped)
    assert monitor.health(monitor.bus_time_s)["state"] == "OK"
