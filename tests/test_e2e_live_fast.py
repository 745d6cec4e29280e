"""``E2EMonitor.check``'s usual frame in line (an on-time frame, CRC right, COUNTER one on, no
silence before it: OK without a ``SequenceState.check`` call) against the same monitor made to
take ``SequenceState.check`` on every frame: the same status of every frame and the same counts,
on sequences of several messages with drops, repeats, CRC errors, silences, restarts and jitter."""

from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from odocan.host.protocol.e2e import e2e_messages
from odocan.host.protocol.e2e_live import E2EMonitor
from odocan.sim.contract import database
from tests.host_frames import p02_protect

DB = database()
CONFIGS = [c for c in e2e_messages(DB).values() if c.data_ids is not None]
IDS = [DB.get_message_by_name(c.name).frame_id for c in CONFIGS]

# per frame: message index, gap in 0.1 ms, COUNTER step (0: repeat, 1: next, more: lost),
# CRC flipped, a restart of the sequence before it
FRAME = st.tuples(st.integers(0, len(CONFIGS) - 1), st.integers(0, 3000), st.integers(0, 20),
                  st.booleans(), st.integers(0, 30))


def _feed(frames: list[tuple[int, int, int, bool, int]], slow: bool) -> tuple[list[str], object]:
    monitor = E2EMonitor()
    counters = [0] * len(CONFIGS)
    t_s = 0.0
    statuses = []
    for index, gap, step, flipped, restart in frames:
        config = CONFIGS[index]
        assert config.data_ids is not None
        t_s += gap * 1e-4
        counters[index] = (counters[index] + step) & 0xF
        buf = bytearray(8)
        buf[2:] = bytes([gap & 0xFF, step, 3, 4, 5, 6])
        p02_protect(buf, counters[index], config.data_ids)
        if flipped:
            buf[7] ^= 0x10
        if restart == 0:
            monitor.restart_sequence(IDS[index])
        if slow:  # no gap is shorter than -inf: every frame by ``SequenceState.check``
            for live in monitor._live.values():
                live.silence_s = -math.inf
        statuses.append(monitor.check(IDS[index], bytes(buf), False, t_s))
    return statuses, monitor.counts()


@settings(max_examples=400, deadline=None)
@given(frames=st.lists(FRAME, min_size=1, max_size=120), clean=st.integers(0, 100))
def test_the_usual_frame_in_line_judges_as_the_sequence_state(
        frames: list[tuple[int, int, int, bool, int]], clean: int) -> None:
    # mostly on time and in sequence (the fast path's case), the rest as drawn
    frames = frames + [(i % len(CONFIGS), 100, 1, False, 1) for i in range(clean)] + frames
    assert _feed(frames, slow=False) == _feed(frames, slow=True)


def test_the_in_line_path_is_taken_and_can_differ_when_wrong() -> None:
    """The fast path runs on a clean sequence (else the test above compares nothing)."""
    config, frame_id = CONFIGS[0], IDS[0]
    assert config.data_ids is not None
    assert config.cycle_s is not None
    monitor = E2EMonitor()
    for k in range(40):
        buf = bytearray(8)
        p02_protect(buf, k, config.data_ids)
        monitor.check(frame_id, bytes(buf), False, k * config.cycle_s)
    state = monitor._live[frame_id].state
    state.counts["ok"] = -1000  # a fast path that counted elsewhere would leave this
    buf = bytearray(8)
    p02_protect(buf, 40, config.data_ids)
    assert monitor.check(frame_id, bytes(buf), False, 40 * config.cycle_s) == "ok"
    assert state.counts["ok"] == -999
    assert state.last_valid == 40 & 0xF
