"""The twist's DISTANCE going back as a reboot's evidence (``host.judge.distfall``, issue #11).

Independent of the rule's code: twist frames are built here with cantools from the DBC and
protected with the test's own E2E Profile 2 (``tests.host_frames``), the expected answer written
from the DBC's DISTANCE (path length since power-up, 1 mm per LSB, wrapping at 65.536 m).
Both the log's reading (``fall_times``, whole and chunked) and the live one (``fell_within`` on
the kept bytes) must give it. Drives without a reboot never show a fall.
"""

from __future__ import annotations

import random
from pathlib import Path

import can
import pytest

from odocan.firmware import frames as fr
from odocan.host.io.logs import iter_log, read_log
from odocan.host.judge.bootticks import tied_to_boot
from odocan.host.judge.distfall import (
    distance_field,
    fall_times,
    falls,
    fell_within,
)
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import e2e_messages
from odocan.sim.board import TICK_S
from tests import host_frames as hf
from tests.test_first_second_reboot import DB, _written, drive

SMALL = 4  # the new firmware's first 80 ms of twists: COUNTER 0..3
TWIST = DB.get_message_by_name("ODOM_TWIST")


def _twist(t_s: float, counter: int, distance_m: float, crc_ok: bool = True) -> can.Message:
    """An ODOM_TWIST from cantools, E2E-protected by the test's own P02."""
    data = bytearray(DB.encode_message(TWIST.frame_id, {
        "CHECKSUM": 0, "COUNTER": counter, "ENC_COUNTER": counter, "LINEAR_VEL": 0.2,
        "ANGULAR_VEL": 0.0, "DISTANCE": distance_m}))
    hf.p02_protect(data, counter, fr.ODOM_TWIST_DATA_IDS)
    if not crc_ok:
        data[0] ^= 0x5A
    return can.Message(arbitration_id=TWIST.frame_id, data=bytes(data), is_extended_id=False,
                       timestamp=t_s)


# (the pair of twists: (t s, COUNTER, DISTANCE m, CRC right), whether the second fell)
CASES = [
    (((0.30, 15, 0.084, True), (0.32, 0, 0.000, True)), True),  # a power-up's twist
    (((0.30, 15, 0.084, True), (0.36, 2, 0.020, True)), True),  # its first two lost
    (((0.30, 15, 0.084, True), (0.32, 0, 0.083, True)), True),  # 1 mm back is a new life
    (((0.30, 15, 0.084, True), (0.32, 0, 0.084, True)), False),  # standing: no fall
    (((0.30, 15, 0.084, True), (0.32, 0, 0.090, True)), False),  # on
    (((0.30, 3, 0.084, True), (0.40, 8, 0.000, True)), False),  # COUNTER past 80 ms
    (((0.30, 15, 65.530, True), (0.32, 0, 0.004, True)), False),  # the 65.536 m wrap
    (((0.30, 15, 0.084, True), (1.40, 0, 0.000, True)), False),  # 1.1 s apart: could wrap
    (((0.30, 15, 0.084, True), (0.32, 0, 0.000, False)), False),  # its CRC wrong
    (((0.30, 15, 0.084, False), (0.32, 0, 0.000, True)), False),  # nothing right before
]


@pytest.mark.parametrize(("pair", "fell"), CASES)
def test_the_log_and_the_live_reading_tell_a_fall_alike(
    pair: tuple[tuple[float, int, float, bool], ...], fell: bool, tmp_path: Path
) -> None:
    messages = tuple(_twist(*twist) for twist in pair)
    frames = read_log(_written(messages, tmp_path / "pair.log"))
    found, _ = fall_times(frames, BulkDecoder(DB), SMALL)
    assert (len(found.times_s) == 1) is fell
    field = distance_field(TWIST, e2e_messages(DB)[TWIST.frame_id])
    heard = [(m.timestamp, bytes(m.data)) for m in messages]
    assert fell_within(field, heard, lambda t_s, _c, _b: 0.0 <= t_s <= 2.0, SMALL) is fell


def test_the_rule_on_raw_values() -> None:
    """``falls`` itself: below by less than half a wrap, within 1 s, a small COUNTER."""
    assert falls(84, 0.30, 0, 0.32, 0, 65536, SMALL)
    assert not falls(65530, 0.30, 4, 0.32, 0, 65536, SMALL)
    assert not falls(84, 0.30, 84, 0.32, 0, 65536, SMALL)
    assert not falls(84, 0.32, 0, 0.30, 0, 65536, SMALL)  # heard out of order (a hold's replay)


@pytest.mark.parametrize("chunk", [7, 97, 100_000])
def test_a_chunked_reading_finds_the_fall_of_a_reboot_once(chunk: int, tmp_path: Path) -> None:
    """A real reset at tick 32: one fall, at the new firmware's first twist, whatever the
    chunks (``stream_lives`` carries the latest twist over)."""
    messages = drive(32)
    path = _written(messages, tmp_path / "reset.log")
    decoder, carried, found = BulkDecoder(DB), None, []
    for frames in iter_log(path, chunk_frames=chunk):
        falls, carried = fall_times(frames, decoder, SMALL, carried)
        found += falls.times_s.tolist()
    new_first = min(m.timestamp for m in messages if m.arbitration_id == TWIST.frame_id
                    and m.timestamp >= 32 * TICK_S)
    assert found == [new_first]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_drive_without_a_reboot_never_falls(seed: int, tmp_path: Path) -> None:
    """pmir on the circle 4 s, no reset, a fifth of its frames lost at random: no fall."""
    rng = random.Random(seed)
    messages = tuple(m for m in drive(10_000) if rng.random() > 0.2)
    frames = read_log(_written(messages, tmp_path / "quiet.log"))
    assert len(fall_times(frames, BulkDecoder(DB), 16)[0].times_s) == 0  # any COUNTER
    field = distance_field(TWIST, e2e_messages(DB)[TWIST.frame_id])
    heard = [(m.timestamp, bytes(m.data)) for m in messages
             if m.arbitration_id == TWIST.frame_id]
    assert not fell_within(field, heard, lambda _t, _c, _b: True, 16)


def test_a_fall_ties_to_a_boot_summary_by_the_next_summary() -> None:
    """``bootticks.tied_to_boot`` on the boot summary at 0.321 s (a reset at tick 32): the
    power-up tick's twist (COUNTER 0) before it, COUNTER 1..3 within 80 ms after it, COUNTER 4
    and 5 heard by the next summary (80, 100 ms on); not a COUNTER more than the time since
    allows, nor a twist after the next summary (the DBC's cycles: 20 ms twist and pose, 100 ms
    summary)."""
    assert DB.get_message_by_name("ODOM_TWIST").cycle_time == 20
    assert DB.get_message_by_name("ODOM_POSE_X").cycle_time == 20
    assert DB.get_message_by_name("ODOM_STATUS").cycle_time == 100
    assert tied_to_boot(0.321, 0, 0.321)
    assert tied_to_boot(0.301, 0, 0.321)
    assert tied_to_boot(0.341, 1, 0.321)
    assert tied_to_boot(0.401, 4, 0.321)
    assert tied_to_boot(0.421, 5, 0.321)
    assert not tied_to_boot(0.341, 4, 0.321)  # 4 twists counted in 20 ms: an older life's
    assert not tied_to_boot(0.441, 6, 0.321)  # after the next summary
    assert not tied_to_boot(0.221, 0, 0.321)  # 100 ms before it
