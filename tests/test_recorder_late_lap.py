"""A recorder that stamps the frame before its chunk 8 periods late or more gets the chunk's
COUNTER lap at the right step (issue #11, rule 3: docs/bus.md's open 'stamps off by 8 periods
or more').

The chunk of ``N`` periods (N >= 16) follows encoder frame f, whose period the recorder stamped
``late`` periods late and read before it lost the chunk. The stamps then say 1 + late periods
from f - 1 to f (COUNTER step 1) and N - late to the frame after the chunk. Each step's lap was
the nearest to its own stamps: for late >= 9 the single step (f - 1, f) took a lap (17 periods,
a gap with its allowance) and the chunk one lap fewer (the sum right: the firmware's pages saw
nothing wrong). Before, on a kobuki drive, a firmware whose X went 1 LSB low (or 2 high) at
that single step PASSed all three judges, hidden in the phantom gap's allowance; with late 12
or 13 a correct firmware FAILed the whole-log and the streamed ``analyze`` (the chunk's
allowance a lap short). Stamps are late, never early: the lap before f put f's true time after
its stamp, every frame around it late and f alone on time (``senderseq.late_lone_frames``).

Which firmware is right, ``tests.independent_checker`` tells on the complete log (float64
odometry and cantools); how many periods each step spans, the complete log's frames tell.
The live judge numbered a frame when it came, before the frames after it showed that it came
late: it PASSed the firmware 1 LSB low at late 10 and FAILed the correct one at late 13 (its
gate refused the chunk's frames, 0.47 m); its samples after such a lap now wait for the 16
frames after it (``host.judge.livelaphold``).
"""

from __future__ import annotations

from pathlib import Path

import can
import numpy as np
import pytest

import tests.test_recorder_holes as holes
from odocan.firmware import frames as fw_frames
from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from odocan.host.judge.holepages import page_numbered
from odocan.host.judge.samples import encoder_frames
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import check_frames
from odocan.sim.contract import database
from odocan.sim.robot import load
from tests.host_frames import p02_protect
from tests.independent_checker import check
from tests.test_capture_jitter import _live_passes
from tests.test_recorder_gap16 import _robot, _time_s

ROBOT = "kobuki"
CHUNK_AT_S = 2.5  # the chunk follows the first encoder frame from here (a pose names it)
BURST_PERIODS = 3  # after the chunk, the frames of so many periods read (stamped) at once


@pytest.fixture(scope="module")
def clean(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("late_lap") / "clean.log"
    main(["run", "--robot", ROBOT, "--scenario", "random", "--duration", "7", "--seed", "3",
          "--log", str(path)])
    return path


def _chunked(log: Path, out: Path, periods: int, late: int,
             monkeypatch: pytest.MonkeyPatch) -> None:
    """``log`` less a chunk of ``periods`` after the first encoder frame at ``CHUNK_AT_S``, that
    frame's period stamped ``late`` periods late (``test_recorder_holes._holed``)."""
    monkeypatch.setattr(holes, "HOLES", ((CHUNK_AT_S, periods, late, BURST_PERIODS),))
    holes._holed(log, out)


def _x_off_from_the_chunk(clean: Path, out: Path, lsb: int) -> None:
    """``clean`` with every ODOM_POSE_X from the chunk's first encoder frame on ``lsb`` LSB off
    (re-protected): a firmware wrong at the single step before the chunk."""
    lines = clean.read_text().splitlines()
    first_s = next(t for t in (_time_s(line) for line in lines if " 100#" in line)
                   if t >= CHUNK_AT_S)
    pose_x = database().get_message_by_name("ODOM_POSE_X")
    with can.LogReader(clean) as reader, can.Logger(out) as writer:
        for msg in reader:
            if msg.arbitration_id == pose_x.frame_id and msg.timestamp >= first_s:
                raw = pose_x.decode(bytes(msg.data), decode_choices=False, scaling=False)
                assert isinstance(raw, dict)
                x_raw = raw["X"]
                assert isinstance(x_raw, int)
                raw["X"] = x_raw + lsb
                data = bytearray(pose_x.encode(raw, scaling=False))
                p02_protect(data, data[1], fw_frames.ODOM_POSE_X_DATA_IDS)
                msg.data = data
            writer.on_message_received(msg)


def _periods(log: Path) -> tuple[np.ndarray, np.ndarray]:
    """The encoder frames' (COUNTER, LEFT, RIGHT) and their sequence numbers as the whole-log
    judge numbers them (its holes raised by the pages, as ``analyze`` does)."""
    db = default_plan()
    decoder = BulkDecoder(db)
    frames = read_log(log)
    enc = page_numbered(frames, decoder, encoder_frames(frames, check_frames(frames, db)[1],
                                                        decoder))
    return np.stack((enc.counter, enc.left, enc.right), axis=1), enc.seq


@pytest.mark.parametrize("periods", [17, 20, 30])
@pytest.mark.parametrize("late", [9, 10, 12, 13])
def test_each_step_spans_its_own_periods(clean: Path, tmp_path: Path, periods: int, late: int,
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """Before: for every case here, (f - 1, f) numbered 17 periods and the chunk a lap short."""
    chunked = tmp_path / "chunked.log"
    _chunked(clean, chunked, periods, late, monkeypatch)
    keys, seq = _periods(chunked)
    all_keys, all_seq = _periods(clean)  # every frame: its number is its period
    where = {tuple(k): int(s) for k, s in zip(all_keys[:300].tolist(), all_seq[:300].tolist(),
                                              strict=True)}  # the drive, not its rest at the end
    kept = np.array([where.get(tuple(k), -1) for k in keys[:260].tolist()])
    assert (kept >= 0).all()
    assert np.diff(seq[:260]).tolist() == np.diff(kept).tolist()


def _verdicts(clean: Path, tmp_path: Path, lsb: int, late: int,
              monkeypatch: pytest.MonkeyPatch) -> tuple[bool, dict[str, bool]]:
    """The independent checker's verdict on the complete log, the judges' on the chunked one
    (a chunk of 20 periods)."""
    wrong, chunked = tmp_path / "wrong.log", tmp_path / "chunked.log"
    _x_off_from_the_chunk(clean, wrong, lsb)
    independent = check(wrong, _robot(ROBOT), "exact", lambda _t: (0.0, 0.0, 0.0)).passed
    _chunked(wrong, chunked, 20, late, monkeypatch)
    return independent, {
        "whole": analyze(read_log(chunked), load(ROBOT), "exact").passed,
        "streamed (CLI)": main(["analyze", str(chunked), "--robot", ROBOT,
                                "--stream", "always"]) == 0,
    }


@pytest.mark.parametrize("late", [10, 12, 13])
def test_a_correct_firmware_passes(clean: Path, tmp_path: Path, late: int,
                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """Before: PASS at late 10, FAIL at 12 and 13 (whole and streamed)."""
    independent, verdicts = _verdicts(clean, tmp_path, 0, late, monkeypatch)
    assert independent
    assert all(verdicts.values()), verdicts


@pytest.mark.parametrize("lsb", [-1, 2])
def test_a_firmware_wrong_at_the_step_before_the_chunk_fails(
    clean: Path, tmp_path: Path, lsb: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Before: PASS, whole and streamed (and live). X 1 LSB high is within the judge's limit
    at that sample (the correct firmware's own rounding there leans the other way)."""
    independent, verdicts = _verdicts(clean, tmp_path, lsb, 10, monkeypatch)
    assert not independent
    assert not any(verdicts.values()), verdicts


@pytest.mark.parametrize(("lsb", "late"), [(-1, 10), (0, 13)])
def test_live(clean: Path, tmp_path: Path, lsb: int, late: int,
              monkeypatch: pytest.MonkeyPatch) -> None:
    wrong, chunked = tmp_path / "wrong.log", tmp_path / "chunked.log"
    _x_off_from_the_chunk(clean, wrong, lsb)
    _chunked(wrong, chunked, 20, late, monkeypatch)
    assert _live_passes(chunked, ROBOT) == (lsb == 0)
