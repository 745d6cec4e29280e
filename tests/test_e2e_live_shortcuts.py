"""The live E2E check's shortcuts against the rules they stand for: the CRC by place
(``e2e_crc.byte1_table``: one table a byte) against cantools.autosar, and the gaps within which a
frame adds one receive period (``e2e_live.one_period_s``) against ``period_count`` and
``receive_period_count``; then ``E2EMonitor`` on frames whose gaps sit on those edges against
the log check (``check_frames``)."""

from __future__ import annotations

import math
import random

import can
import cantools.autosar
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from odocan.host.io.logs import FrameCollector
from odocan.host.protocol.e2e import check_frames, e2e_messages
from odocan.host.protocol.e2e_crc import crc_right_by_place
from odocan.host.protocol.e2e_evidence import CAPTURE_HOLD_CYCLES
from odocan.host.protocol.e2e_live import E2EMonitor, one_period_s
from odocan.host.protocol.e2e_periods import (
    CAPTURE_TOLERANCE_CYCLES,
    period_count,
    receive_period_count,
)
from odocan.sim.contract import database
from tests.host_frames import p02_protect
from tests.test_host_e2e import autosar_message

DB = database()
CONFIGS = e2e_messages(DB)
CYCLES_S = sorted({c.cycle_s for c in CONFIGS.values() if c.cycle_s} | {0.001, 0.0137, 2.5})


@settings(max_examples=300, deadline=None)
@given(frame=st.binary(min_size=8, max_size=8),
       ids=st.lists(st.integers(0, 255), min_size=16, max_size=16), sealed=st.booleans())
def test_the_crc_by_place_is_cantools_autosar(frame: bytes, ids: list[int], sealed: bool) -> None:
    expected = cantools.autosar.compute_profile2_crc(frame, autosar_message(ids))
    assert expected is not None
    if sealed:  # half the frames carry their right CRC (random bytes almost never do)
        frame = bytes([expected]) + frame[1:]
    assert crc_right_by_place(frame, tuple(ids)) is (frame[0] == expected)


def test_the_crc_by_place_refuses_every_single_bit_flip_of_every_message() -> None:
    rng = random.Random(7)
    for config in CONFIGS.values():
        assert config.data_ids is not None
        for counter in range(16):
            buf = bytearray(rng.randbytes(8))
            p02_protect(buf, counter, config.data_ids)
            assert crc_right_by_place(bytes(buf), config.data_ids), config.name
            for bit in range(64):
                flipped = int.from_bytes(buf, "little") ^ (1 << bit)
                assert not crc_right_by_place(flipped.to_bytes(8, "little"), config.data_ids)


def _gaps_s(cycle_s: float, from_s: float, to_s: float) -> list[float]:
    """Gaps on and next to both edges, and a grid between."""
    edges = [g for e in (from_s, to_s) if math.isfinite(e)
             for g in (e, math.nextafter(e, math.inf), math.nextafter(e, -math.inf))]
    low = from_s if math.isfinite(from_s) else -cycle_s
    return [*edges, *(low + (to_s - low) * k / 200 for k in range(201))]


@pytest.mark.parametrize("cycle_s", CYCLES_S)
def test_a_gap_within_one_period_s_adds_one_period_by_every_rule(cycle_s: float) -> None:
    from_s, to_s = one_period_s(cycle_s, 1)
    for dt_s in _gaps_s(cycle_s, from_s, to_s):
        if from_s <= dt_s <= to_s:
            assert period_count(dt_s, cycle_s, 1) == 1, dt_s
    from_s, to_s = one_period_s(cycle_s, 0)
    for dt_s in _gaps_s(cycle_s, from_s, to_s):
        if from_s <= dt_s <= to_s:
            assert period_count(dt_s, cycle_s, 0) == 1, dt_s  # a wrong CRC on either side
            for tolerance in (CAPTURE_TOLERANCE_CYCLES, CAPTURE_HOLD_CYCLES):
                assert receive_period_count(dt_s, 1, cycle_s, tolerance) == 1, dt_s


def test_without_a_cycle_no_gap_is_within_one_period() -> None:
    for min_periods in (0, 1, 2):
        from_s, to_s = one_period_s(None, min_periods)
        assert not from_s <= 0.0 <= to_s
    from_s, to_s = one_period_s(0.01, 2)
    assert not from_s <= 0.01 <= to_s


def _frames(rng: random.Random, name: str, n: int) -> list[tuple[float, bytes]]:
    """``n`` frames of ``name``: gaps near one period's edges (and off them), COUNTER steps
    mostly 1, some CRCs broken."""
    config = next(c for c in CONFIGS.values() if c.name == name)
    assert config.data_ids is not None
    assert config.cycle_s is not None
    edges = [e for m in (0, 1) for e in one_period_s(config.cycle_s, m) if math.isfinite(e)]
    t_s, counter, frames = 0.0, 0, []
    for _ in range(n):
        roll = rng.random()
        gap_s = (rng.choice(edges) * (1 + rng.uniform(-1e-6, 1e-6)) if roll < 0.6
                 else config.cycle_s * rng.choice([0.5, 1.5, 2, 3, 0.01, 9, 17.3, 40.7]))
        t_s += gap_s
        counter = (counter + rng.choice([1] * 12 + [0, 2, 3, 9])) & 0xF
        buf = bytearray(rng.randbytes(8))
        p02_protect(buf, counter, config.data_ids)
        if rng.random() < 0.05:
            buf[5] ^= 0x04
        frames.append((t_s, bytes(buf)))
    return frames


@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize("name", ["WHEEL_ENCODERS", "ODOM_POSE_X", "SIM_TRUTH"])
def test_frames_on_the_edges_are_judged_as_the_log_check_judges_them(seed: int,
                                                                    name: str) -> None:
    frames = _frames(random.Random(seed), name, 300)
    frame_id = DB.get_message_by_name(name).frame_id
    monitor = E2EMonitor(DB)
    statuses = [monitor.check(frame_id, data, timestamp_s=t_s) for t_s, data in frames]
    collector = FrameCollector()
    for t_s, data in frames:
        collector.on_message_received(can.Message(timestamp=t_s, arbitration_id=frame_id,
                                                  data=data, is_extended_id=False))
    counts, accepted = check_frames(collector.arrays(), DB)
    live = monitor.counts()[name]
    assert live == counts[name]  # ``silence_ms`` too: each silence rounded on its own in both
    assert [s in ("ok", "oksomelost") for s in statuses] == accepted.tolist()
