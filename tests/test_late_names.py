"""The late-naming rule (``host.judge.latenames``) reads only frames held back on the bus as late
(issue #11: its first cut read a rebooted firmware's COUNTER starting again as a run of frames
held back 100 ms, so the whole log's twist check of ``tests/test_stream_facts.py``'s rig log, a
drop/dup/flip bus with a stall and a reboot and no delay, FAILed 0.30 rad/s where the streamed
judge PASSed, and the awkward log's repeated and swapped frames moved its samples, 380 -> 382),
and reads them alike fed in the streamed judge's chunks (``LateScan``), where the stream refuses
a life with one taken (``stream_late``: the whole log's judge names it where it was sent)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from odocan.host.io.logs import FrameArrays, iter_log, read_log
from odocan.host.judge.latenames import LateScan, crc_right_positions, late_sends, sent_places
from odocan.host.judge.stream_late import LATE_MESSAGES, StreamLate
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK, POSE_PERIOD_S
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import check_frames
from odocan.sim.contract import database
from tests.test_delay_long import DRIVES, _drive
from tests.test_stream_facts import log_of

PERIOD = POSE_PERIOD_S


def _late(heard: list[float], counter: list[int]) -> list[bool]:
    late, _ = late_sends(np.array(heard), np.array(counter, dtype=np.int64), PERIOD)
    return [bool(x) for x in late]


def test_a_rebooted_sender_starting_its_counter_again_is_not_late() -> None:
    """COUNTER 0-4 at 1.901-1.981 s, the firmware reboots and sends 0-7 from 2.001 s: each new
    frame's COUNTER lies 4 to 0 sends behind the 4, but its send is one heard already (the old
    life's frame of that COUNTER): a repeat, not a frame held back. So with the old 2 lost:
    the new 2 follows the new 1 at the sender's cadence."""
    old = [1.901 + 0.02 * k for k in range(5)]
    new = [2.001 + 0.02 * k for k in range(8)]
    counters = [0, 1, 2, 3, 4, 0, 1, 2, 3, 4, 5, 6, 7]
    assert _late(old + new, counters) == [False] * 13
    lost = [k for k in range(13) if k != 2]
    assert _late([(old + new)[k] for k in lost], [counters[k] for k in lost]) == [False] * 12


def test_a_duplicate_and_a_swapped_pair_are_not_late() -> None:
    """A frame the bus sent twice (COUNTER 1 again at once) repeats a send heard; a frame heard
    after its successor (2 after 3) came a period late, where its name is still resolved
    unambiguously: neither is moved. A frame held back 7 periods (6 after 13) is."""
    heard = [1.001, 1.021, 1.0211, 1.061, 1.0611, 1.081, 1.101, 1.261, 1.2611]
    counter = [0, 1, 1, 3, 2, 4, 5, 13, 6]
    assert _late(heard, counter) == [False] * 8 + [True]


def test_a_halt_of_half_a_lap_after_a_straggler_is_not_lateness() -> None:
    """pmir random 3, ``delay=0.2:40,stall=2:0.1`` (the twists of 1.941 to 2.241 s): COUNTER 2
    held back 40 ms behind 3, then the firmware halted 100 ms (2.0 to 2.1 s) and sent 4 on at
    its cadence. The straggler says nothing of the sends after the silence: they are on time,
    as they are read without it. Read as a run held back 100 ms (half an encoder COUNTER lap
    and more), they named encoder frames a lap back: run and analyze FAILed the correct
    firmware's DISTANCE by 35.6 mm (``tests/test_live_swappedskips.py``'s ``HALT_DRIVES``)."""
    heard = [1.941, 1.981, 2.001, *(2.101 + 0.02 * k for k in range(8))]
    counter = [1, 3, 2, *range(4, 12)]
    assert _late(heard, counter) == [False, False, True] + [False] * 8
    without = [k for k in range(len(heard)) if k != 2]  # the same sends, no straggler
    assert _late([heard[k] for k in without], [counter[k] for k in without]) == [False] * 10


def _scan_in_pieces(t: np.ndarray, c: np.ndarray, size: int) -> tuple[list[bool], list[float]]:
    scan, late, sent = LateScan(PERIOD), [], []
    for lo in range(0, len(t), size):
        part = scan.feed(t[lo:lo + size].tolist(), c[lo:lo + size].tolist())
        late += part[0]
        sent += part[1]
    return late, sent


def _message(frames: FrameArrays, name: str) -> tuple[np.ndarray, np.ndarray]:
    good = crc_right_positions(frames, BulkDecoder(database()), name)
    return (frames.timestamp_s[good],
            (frames.data[good, 1] & ENC_COUNTER_MASK).astype(np.int64))


@pytest.fixture(scope="module")
def delayed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    robot, seed, faults = DRIVES["pmir_1"]
    return _drive(tmp_path_factory.mktemp("late"), robot, seed, faults)[0]


@pytest.mark.parametrize("size", [1, 2, 7, 64])
def test_the_scan_in_pieces_is_the_whole_scan(delayed: Path, size: int) -> None:
    frames = read_log(delayed)
    for name in LATE_MESSAGES:
        t, c = _message(frames, name)
        want_late, want_sent = late_sends(t, c, PERIOD)
        assert want_late.sum() > 20, name  # the delayed drive's frames held back 150 ms
        late, sent = _scan_in_pieces(t, c, size)
        assert late == want_late.tolist(), name
        assert sent == want_sent.tolist(), name


def _stream_finds(path: Path, chunk_frames: int) -> bool:
    db = database()
    late = StreamLate(BulkDecoder(db))
    _, accepted = check_frames(read_log(path), db)
    at = 0
    for chunk in iter_log(path, chunk_frames=chunk_frames):
        late.feed(chunk, accepted[at:at + len(chunk)])
        at += len(chunk)
    return late.found


@pytest.mark.parametrize("which", ["awkward", "rig"])
def test_a_log_without_delay_names_every_frame_where_heard(tmp_path: Path, which: str) -> None:
    """test_stream_facts' two logs (reboots, a counter restart, repeated, swapped, dropped and
    corrupted frames, a stall; no delay): the rule moves no frame, and the stream finds none
    to refuse for."""
    path = log_of(tmp_path, which)
    frames, db = read_log(path), database()
    decoder = BulkDecoder(db)
    _, accepted = check_frames(frames, db)
    for name in LATE_MESSAGES:
        rows = decoder.decode(frames, name)
        index = rows["index"][accepted[rows["index"]]].astype(np.int64)
        t = frames.timestamp_s[index]
        places, _, times = sent_places(frames, decoder, name, index, t,
                                       np.zeros(len(index), dtype=np.int64))
        if which == "rig" or name != "ODOM_TWIST":  # the synthesized log has no ODOM_TWIST
            assert len(index) > 100, name
        np.testing.assert_array_equal(places, index, err_msg=name)
        np.testing.assert_array_equal(times, t, err_msg=name)
    assert not _stream_finds(path, 7)


@pytest.mark.parametrize("chunk_frames", [1, 64])
def test_the_stream_finds_the_late_frames_the_rule_moves(delayed: Path,
                                                        chunk_frames: int) -> None:
    """On the delayed drive the rule moves accepted pose frames, and the stream finds them
    (its life is then judged whole, by the rule)."""
    frames, db = read_log(delayed), database()
    decoder = BulkDecoder(db)
    _, accepted = check_frames(frames, db)
    rows = decoder.decode(frames, "ODOM_POSE_X")
    index = rows["index"][accepted[rows["index"]]].astype(np.int64)
    places, _, _ = sent_places(frames, decoder, "ODOM_POSE_X", index, frames.timestamp_s[index],
                               np.zeros(len(index), dtype=np.int64))
    assert np.count_nonzero(places != index) > 10
    assert _stream_finds(delayed, chunk_frames)
