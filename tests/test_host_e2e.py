"""The host's E2E Profile 2 receiver against cantools.autosar (CRC) and the firmware (sequence).

The host has its own implementation (``host.e2e``); the firmware's ``E2EReceiver`` is only used
here, as the other side of the comparison.
"""

from __future__ import annotations

import random

import can
import cantools.autosar
import numpy as np
import pytest
from cantools.database.can.formats.arxml.end_to_end_properties import AutosarEnd2EndProperties
from cantools.database.can.formats.arxml.message_specifics import AutosarMessageSpecifics
from hypothesis import given, settings
from hypothesis import strategies as st

from odocan.firmware.e2e import E2EReceiver, E2EStatus
from odocan.host.io.logs import FrameArrays, FrameCollector
from odocan.host.protocol.e2e import (
    CRC8H2F_TABLE,
    E2E_KEYS,
    UNKNOWN,
    check_frames,
    crc8h2f_p02,
    crc8h2f_p02_one,
)
from odocan.host.protocol.e2e_cycles import new_cycles
from odocan.host.protocol.e2e_live import E2EMonitor
from odocan.sim.contract import database
from tests.dbc_typed import dbc_attribute
from tests.host_frames import p02_protect

DB = database()
ENC = DB.get_message_by_name("WHEEL_ENCODERS")
ENC_IDS = tuple(int(v) for v in dbc_attribute(ENC, "E2EDataIDs").split(","))
CYCLE_S = 0.01
FW_STATUS = {
    E2EStatus.OK: "ok", E2EStatus.OKSOMELOST: "oksomelost", E2EStatus.REPEATED: "repeated",
    E2EStatus.WRONGSEQUENCE: "wrong_sequence", E2EStatus.ERROR: "crc_error",
}


def autosar_message(data_ids: list[int]) -> cantools.database.can.Message:
    """A cantools message carrying a Profile 2 data-ID list, as the ARXML loader would make it."""
    message = DB.get_message_by_name("ODOM_POSE_X")
    copy = cantools.database.can.Message(
        frame_id=message.frame_id, name="X", length=8, signals=[]
    )
    e2e = AutosarEnd2EndProperties()
    e2e.category = "PROFILE_02"
    e2e.data_ids = data_ids
    e2e.payload_length = 8
    copy.autosar = AutosarMessageSpecifics()
    copy.autosar.e2e = e2e
    return copy


def test_crc_table_is_crc8h2f() -> None:
    assert CRC8H2F_TABLE[1] == 0x2F
    # AUTOSAR check value: CRC("123456789") = 0xDF, computed with the same table
    crc = 0xFF
    for byte in b"123456789":
        crc = int(CRC8H2F_TABLE[crc ^ byte])
    assert crc ^ 0xFF == 0xDF


@settings(max_examples=50, deadline=None)
@given(
    frames=st.lists(st.binary(min_size=8, max_size=8), min_size=1, max_size=64),
    ids=st.lists(st.integers(0, 255), min_size=16, max_size=16),
)
def test_vectorised_crc_equals_cantools_autosar(frames: list[bytes], ids: list[int]) -> None:
    data = np.frombuffer(b"".join(frames), dtype=np.uint8).reshape(-1, 8)
    data_ids = np.array(ids, dtype=np.uint8)[data[:, 1] & 0xF]
    ours = crc8h2f_p02(data, data_ids)
    message = autosar_message(ids)
    for i, frame in enumerate(frames):
        expected = cantools.autosar.compute_profile2_crc(frame, message)
        assert int(ours[i]) == expected
        assert crc8h2f_p02_one(frame, ids[frame[1] & 0xF]) == expected


# --- sequences ------------------------------------------------------------------------------


def encoder_frame(counter: int, corrupt: bool = False) -> bytes:
    """A WHEEL_ENCODERS frame of ``counter`` (CRC broken when ``corrupt``)."""
    buf = bytearray(b"\x00\x00\x01\x02\x03\x04\x05\x06")
    p02_protect(buf, counter, ENC_IDS)
    if corrupt:
        buf[4] ^= 0x10
    return bytes(buf)


def frames_at(events: list[tuple[int, bytes]], can_id: int = ENC.frame_id) -> FrameArrays:
    """Frames of one ID at the given periods (tick numbers)."""
    collector = FrameCollector()
    for tick, data in events:
        collector.on_message_received(
            can.Message(timestamp=tick * CYCLE_S, arbitration_id=can_id, data=data,
                        is_extended_id=False)
        )
    return collector.arrays()


def firmware_statuses(events: list[tuple[int, bytes]]) -> list[str]:
    """The firmware's WHEEL_ENCODERS receiver (firmware/encoders.py: MaxDeltaCounterInit 0, the
    window widened once per tick, ``new_period``) fed the same frames, with ``check(None)`` in
    each empty period; frames of one tick share its period."""
    rx = E2EReceiver(ENC_IDS, max_delta_counter_init=0, window_per_period=True)
    result = []
    tick = events[0][0] if events else 0
    for when, data in events:
        while tick < when:  # a new period each tick; the empty ones end with check(None)
            tick += 1
            rx.new_period()
            if tick < when:
                rx.check(None)
        result.append(FW_STATUS[rx.check(data)])
    return result


def host_view(events: list[tuple[int, bytes]], statuses: list[str]) -> list[str]:
    """The firmware's ``statuses`` of ``events`` as the host gives them: a frame the firmware
    refused as REPEATED 8 ticks or more after the last frame the host accepted, with no frame
    refused (its CRC right) between, is the sender's frame 16 * k periods on to the host
    (``host.protocol.e2e.SequenceState.cycle_s``: a recorder that lost the frames between,
    which the firmware had, would otherwise leave the host a frame short of it); the intended
    difference, the only one (its window is kept). Exactly 8 ticks is the edge: decided on the
    float64 stamps as ``samples.sender_seq`` does."""
    result: list[str] = []
    last_tick: int | None = None  # the last accepted frame's, None after a refused one
    for (tick, _), status in zip(events, statuses, strict=True):
        if status == "repeated" and last_tick is not None and (
                tick - last_tick > 8 or (tick - last_tick == 8 and new_cycles(
                    tick * CYCLE_S - last_tick * CYCLE_S, CYCLE_S))):
            status = "oksomelost"
        if status in ("ok", "oksomelost"):
            last_tick = tick
        elif status in ("repeated", "wrong_sequence"):
            last_tick = None
        result.append(status)
    return result


def test_a_frame_of_the_same_counter_16_periods_on_is_no_repeat_to_the_host() -> None:
    """Before: REPEATED, as the firmware (which lost the 15 frames too) refuses it; a recorder
    that lost them while the firmware had them left the host a frame short. 7 periods on it
    is a repeat still, and the frames after are judged as the firmware judges them."""
    events = [(0, encoder_frame(3)), (16, encoder_frame(3)), (17, encoder_frame(9)),
              (24, encoder_frame(9)), (25, encoder_frame(10))]
    statuses, accepted = host_statuses(events)
    fw = firmware_statuses(events)
    assert fw == ["ok", "repeated", "oksomelost", "repeated", "ok"]
    assert statuses == host_view(events, fw) == ["ok", "oksomelost", "oksomelost", "repeated",
                                                 "ok"]
    assert accepted.tolist() == [True, True, True, False, True]


def host_statuses(events: list[tuple[int, bytes]]) -> tuple[list[str], np.ndarray]:
    """E2EMonitor's statuses (with timestamps) and check_frames' accepted mask."""
    monitor = E2EMonitor(DB)
    statuses = [
        monitor.check(ENC.frame_id, data, timestamp_s=tick * CYCLE_S) for tick, data in events
    ]
    counts, accepted = check_frames(frames_at(events), DB)
    assert counts["WHEEL_ENCODERS"] == monitor.counts()["WHEEL_ENCODERS"]
    return statuses, accepted


CRAFTED = [
    ("in order", [0, 1, 2, 3], ["ok"] * 4, {"ok": 4}),
    ("wrap", [14, 15, 0, 1], ["ok"] * 4, {"ok": 4}),
    ("repeated", [3, 4, 4, 5], ["ok", "ok", "repeated", "ok"], {"ok": 3, "repeated": 1}),
    (  # only time lets a frame through that jumps the COUNTER (one_lost below)
        "+2 within one period",
        [3, 4, 6, 7],
        ["ok", "ok", "wrong_sequence", "wrong_sequence"],
        {"ok": 2, "wrong_sequence": 2},
    ),
    (
        "jump beyond the window, then re-sync",
        [3, 4, 9, 10, 5],
        ["ok", "ok", "wrong_sequence", "wrong_sequence", "ok"],
        {"ok": 3, "wrong_sequence": 2},
    ),
]


@pytest.mark.parametrize(("what", "counters", "expected", "counts"), CRAFTED)
def test_crafted_sequences(
    what: str, counters: list[int], expected: list[str], counts: dict[str, int]
) -> None:
    events = [(tick, encoder_frame(c)) for tick, c in enumerate(counters)]
    statuses, accepted = host_statuses(events)
    assert statuses == expected, what
    assert firmware_statuses(events) == expected, what
    assert accepted.tolist() == [s in ("ok", "oksomelost") for s in expected]
    full = dict.fromkeys(E2E_KEYS, 0) | counts
    assert check_frames(frames_at(events), DB)[0]["WHEEL_ENCODERS"] == full


def test_one_lost_frame_is_oksomelost() -> None:
    events = [(0, encoder_frame(3)), (1, encoder_frame(4)), (3, encoder_frame(6)),
              (4, encoder_frame(7))]
    statuses, accepted = host_statuses(events)
    assert statuses == firmware_statuses(events) == ["ok", "ok", "oksomelost", "ok"]
    assert accepted.all()
    counts = check_frames(frames_at(events), DB)[0]["WHEEL_ENCODERS"]
    assert counts == dict.fromkeys(E2E_KEYS, 0) | {"ok": 4, "lost": 1}


def test_a_second_frame_in_one_period_does_not_widen_the_window() -> None:
    """A forger's frame sent with a genuine one (tests/test_forged_pairing.py): +2 refused."""
    events = [(0, encoder_frame(3)), (0, encoder_frame(5)), (1, encoder_frame(4)),
              (2, encoder_frame(5))]
    statuses, _ = host_statuses(events)
    assert statuses == firmware_statuses(events) == ["ok", "wrong_sequence", "ok", "ok"]


def test_window_widens_with_time_like_the_firmware() -> None:
    # +4 one period later: wrong sequence; +4 four periods later (three empty): OKSOMELOST
    near = [(0, encoder_frame(0)), (1, encoder_frame(4))]
    far = [(0, encoder_frame(0)), (4, encoder_frame(4))]
    assert host_statuses(near)[0] == firmware_statuses(near) == ["ok", "wrong_sequence"]
    assert host_statuses(far)[0] == firmware_statuses(far) == ["ok", "oksomelost"]


def test_corrupted_frames_are_crc_errors_and_never_accepted() -> None:
    events = [(0, encoder_frame(0)), (1, encoder_frame(1, corrupt=True)), (2, encoder_frame(2))]
    statuses, accepted = host_statuses(events)
    assert statuses == firmware_statuses(events) == ["ok", "crc_error", "oksomelost"]
    assert accepted.tolist() == [True, False, True]


@pytest.mark.parametrize("seed", range(40))
def test_random_sequences_match_the_firmware(seed: int) -> None:
    rng = random.Random(seed)
    events = []
    tick, counter = 0, rng.randrange(16)
    for _ in range(rng.randint(1, 400)):
        tick += rng.choice([1] * 8 + [2, 3, 7, 20])
        roll = rng.random()
        if roll < 0.1:
            counter = rng.randrange(16)
        elif roll > 0.15:
            counter = (counter + 1) & 0xF
        events.append((tick, encoder_frame(counter, corrupt=rng.random() < 0.05)))
    statuses, accepted = host_statuses(events)
    expected = host_view(events, firmware_statuses(events))
    assert statuses == expected
    assert accepted.tolist() == [s in ("ok", "oksomelost") for s in expected]


def test_unknown_frames_are_counted_not_fatal() -> None:
    collector = FrameCollector()
    messages = [
        can.Message(
            timestamp=0.0, arbitration_id=0x100, data=encoder_frame(0), is_extended_id=False
        ),
        can.Message(timestamp=0.01, arbitration_id=0x555, data=bytes(8), is_extended_id=False),
        can.Message(timestamp=0.02, arbitration_id=0x100, data=bytes(8), is_extended_id=True),
        can.Message(timestamp=0.03, arbitration_id=0x100, data=bytes(4), is_extended_id=False),
        can.Message(timestamp=0.04, is_error_frame=True),
        can.Message(timestamp=0.05, arbitration_id=0x100, is_remote_frame=True, dlc=8,
                    is_extended_id=False),
    ]
    for msg in messages:
        collector.on_message_received(msg)
    counts, accepted = check_frames(collector.arrays(), DB)
    assert counts[UNKNOWN] == {
        "unknown_id": 2, "wrong_dlc": 1, "error_frames": 1, "remote_frames": 1, "unprotected": 0,
    }
    assert counts["WHEEL_ENCODERS"]["ok"] == 1
    assert accepted.tolist() == [True, False, False, False, False, False]
    monitor = E2EMonitor(DB)
    assert monitor.check(0x555, bytes(8)) == "unknown_id"
    assert monitor.check(0x100, bytes(4)) == "wrong_dlc"
    assert monitor.check(0x100, encoder_frame(5)) == "ok"


def test_restart_sequence_takes_the_next_frame_afresh_and_keeps_the_counts() -> None:
    """A rebooted sender's COUNTER starts again (host.judge.sources.start_new_life): after
    ``restart_sequence`` its next frame is accepted whatever its COUNTER; without it, that
    frame is out of sequence. The counts so far stay."""
    def heard(restart: bool) -> tuple[list[str], dict[str, int]]:
        monitor = E2EMonitor(DB)
        statuses = [monitor.check(ENC.frame_id, encoder_frame(c), timestamp_s=c * 0.01)
                    for c in range(6)]
        if restart:
            monitor.restart_sequence(ENC.frame_id)
        statuses.append(monitor.check(ENC.frame_id, encoder_frame(13), timestamp_s=0.06))
        statuses.append(monitor.check(ENC.frame_id, encoder_frame(14), timestamp_s=0.07))
        return statuses, monitor.counts()["WHEEL_ENCODERS"]

    statuses, counts = heard(restart=True)
    assert statuses == ["ok"] * 8
    assert counts["ok"] == 8
    statuses, _ = heard(restart=False)
    assert statuses[6] != "ok"
