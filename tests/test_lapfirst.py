"""``host.judge.lapfirst``'s choice of a first pose's lap, value by value: the older lap only
when all four values of the tick fit it and not the newest (a wrong pose matching an older lap
in part is not excused)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from odocan.host.io.logs import FrameArrays, read_log
from odocan.host.judge.lapfirst import (
    Said,
    at_start,
    lagged,
    lap_candidates,
    lap_named,
    older_lap,
)
from odocan.host.judge.samples import (
    HEADING_LSB_RAD,
    POSITION_LSB_M,
    Encoders,
    PoseHalves,
    encoder_frames,
)
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import check_frames
from odocan.sim.robot import load
from tests.log_edit import raise_raw_once
from tests.test_reprime_apply import drive
from tests.test_staged_reboot import _written

FILES = Path(__file__).resolve().parent / "files"

NEWEST = Said(0.1833, 0.0081, 0.1251, 0.183)
OLDER = Said(0.1032, 0.0013, 0.0472, 0.103)


def test_the_older_lap_when_every_value_fits_it() -> None:
    said = Said(0.1032 + POSITION_LSB_M, 0.0013, 0.0472 + HEADING_LSB_RAD, 0.104)
    assert older_lap(said, [NEWEST, OLDER]) == 1


def test_the_plain_name_when_one_value_does_not_fit() -> None:
    for said in (OLDER._replace(x_m=0.1032 + 3 * POSITION_LSB_M),
                 OLDER._replace(y_m=0.0013 - 3 * POSITION_LSB_M),
                 OLDER._replace(heading_rad=0.0472 + 3 * HEADING_LSB_RAD),
                 OLDER._replace(distance_m=0.183)):
        assert older_lap(said, [NEWEST, OLDER]) is None, said


def test_the_newest_when_it_fits_too_and_one_of_two_older_that_are_one_pose() -> None:
    """The newest fitting: judged there. Two older ones fitting that are one pose (the robot
    stood still between them): the newer of them, never the newest frame, which FAILs it (the
    candidates rule); two that differ (DISTANCE 3 LSBs apart, both within 2 of the pose): untold."""
    assert older_lap(OLDER, [OLDER, OLDER]) is None  # standing still: the newest
    assert older_lap(OLDER, [NEWEST, OLDER, OLDER]) == 1
    assert older_lap(OLDER, [NEWEST, OLDER, OLDER._replace(x_m=0.1032 + POSITION_LSB_M)]) == 1
    apart = [NEWEST, OLDER._replace(distance_m=0.1015), OLDER._replace(distance_m=0.1045)]
    assert older_lap(OLDER._replace(distance_m=0.103), apart) is None
    assert older_lap(NEWEST, [NEWEST, OLDER]) is None


def test_the_candidates_go_back_by_laps_to_the_life_s_first_frame() -> None:
    seq = np.array([3, 4, 5, 19, 20, 21, 35, 36, 37], dtype=np.int64)
    assert lap_candidates(seq, 8) == [8, 5, 2]  # seq 37, 21, 5
    assert lap_candidates(seq, 6) == [6, 3, 0]  # seq 35, 19, 3 (the life's first)
    assert lap_candidates(seq[1:], 5) == [5, 2]  # seq 35, 19 (3: before the life's first)
    assert lap_candidates(seq, 0) == [0]


def test_the_stream_reads_whole_a_life_whose_first_pose_may_lag(tmp_path: Path) -> None:
    """``lagged``: the streamed judge's gate (``stream_first``): the capture's first pose fits
    frame 53 by heading and DISTANCE (the streamed judge reads it whole, ``lapfirst.REFUSAL``);
    the other capture's, and the capture's with its first HEADING 3 LSBs off, do not."""
    assert _lagged(FILES / "restart_lagged_first_pose.blf")
    assert not _lagged(FILES / "restart_live_two_lsb.blf")
    tampered = tmp_path / "tampered.blf"
    raise_raw_once(FILES / "restart_lagged_first_pose.blf", tampered, "ODOM_POSE_X", (6, 2), 3,
                   0.0)
    assert not _lagged(tampered)


def _lagged(path: Path) -> bool:
    frames = read_log(path)
    db = default_plan()
    _, accepted = check_frames(frames, db)
    return lagged(frames, accepted, BulkDecoder(db), load("pmir"))


@pytest.mark.parametrize("scenario", ["spin", "square"])
def test_a_backlog_pose_after_a_stall_is_left_to_the_stall_rules(
        scenario: str, tmp_path: Path) -> None:
    """The re-prime sweeps' life (pmir reset at 0.1 s, halted 4 s): the firmware's first pose,
    sent at 4.12 s, is its FIFO's backlog pose of the life's first frames, 25 laps before the
    newest of its ENC_COUNTER, and fits it; before, ``lap_named`` moved it there on top of the
    stall rules' own placement and FAILed the correct firmware (12.6 mrad on the spin, 2.7 mm
    on the square). After a stall the name stands (``after_stall``); the capture, which did not
    stall, is still moved. The life as the whole log's judge cuts it: from the reset's summary
    (0.101 s, the firmware's last word before its stall) to the APPLY (4.131 s)."""
    messages = [m for m in drive(scenario, 400, 3) if 0.1005 <= m.timestamp < 4.131]
    frames = read_log(_written(tuple(messages), tmp_path / "life.log"))
    enc, _ = _lap_named(frames)
    assert enc.renamed is None
    enc, _ = _lap_named(read_log(FILES / "restart_lagged_first_pose.blf"))
    assert enc.renamed is not None


def test_a_pose_at_the_life_s_start_is_no_evidence_of_a_lap() -> None:
    """A firmware that primed late on the very frame its first pose names says the life's start
    (``stall=0:1``: (0, 0, 0), DISTANCE 0); near a start at rest an older lap fits it too. The
    plain name stands (``at_start``), the streamed judge no longer refuses that log."""
    assert at_start(Said(0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert at_start(Said(0.5, -1.2, 0.7, 0.001), (0.5, -1.2, 0.7))
    assert not at_start(OLDER, (0.0, 0.0, 0.0))
    assert not at_start(Said(0.0, 0.0, 0.0, 0.003), (0.0, 0.0, 0.0))  # it moved 3 mm


def _lap_named(frames: FrameArrays) -> tuple[Encoders, PoseHalves]:
    db = default_plan()
    decoder = BulkDecoder(db)
    _, accepted = check_frames(frames, db)
    return lap_named(frames, accepted, decoder, encoder_frames(frames, accepted, decoder),
                     (load("pmir"), "exact", None))
