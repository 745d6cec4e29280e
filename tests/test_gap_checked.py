"""gapseen's proof "by checked" (``host.judge.gapchecked``, issue #11): made-up buses where the
firmware's E2E counts must prove it received exactly the log's encoder frames between two pages,
and where they must not (a frame the log lacks that the firmware checked, refused or not).

A bus is a list of encoder frames in bus order, each with the E2E status the firmware gave it,
whether the log holds it and whether the firmware's mailbox dropped it, and ticks where the
firmware made an ENC_E2E page and a FRAME_TOTALS page (its counts then, wrapped as on the wire).
The host's E2E check runs the same check, so it accepts the frames the log holds that the
firmware accepted (``lo``, ``hi`` count those; ``raw_lo``, ``raw_hi`` every frame logged).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from odocan.host.judge.gapchecked import packed
from odocan.host.judge.gapseen import Page, Seen, Totals, seen_of
from odocan.host.judge.pagechain import chained_breaks, chained_ok

OK, REPEATED, CRC, WRONG_SEQ = "ok", "repeated", "crc", "wrong_seq"
TICK, OTHER = "tick", "other"  # pages made; a refusal of another receiver
CYCLE_S = 0.01


@dataclass(frozen=True)
class Frame:
    status: str = OK
    logged: bool = True
    dropped: bool = False  # the firmware's mailbox was full
    host_took: bool = False  # refused by the firmware, accepted by the host (gapskips)


@dataclass
class Bus:
    """The firmware's counts and the log's frames as a bus goes by (module docstring)."""

    counts: dict[str, int] = field(default_factory=lambda: dict.fromkeys((OK, REPEATED, CRC,
                                                                          WRONG_SEQ), 0))
    overflowed: int = 0
    other_rejected: int = 0  # refusals of no encoder E2E check (another receiver's)
    enc: int = 0  # the log's frames the host accepted
    raw: int = 0  # every encoder frame logged
    last_s: float = 0.0
    pages: list[Page] = field(default_factory=list)
    totals: list[Totals] = field(default_factory=list)
    frames: list[tuple[Frame, int]] = field(default_factory=list)  # each with the enc frames
    # logged before it

    def frame(self, frame: Frame, t_s: float) -> None:
        self.frames.append((frame, self.enc))
        if frame.dropped:
            self.overflowed += 1
        else:
            self.counts[frame.status] += 1
        if frame.logged:
            self.raw += 1
            if frame.status == OK or frame.host_took:
                self.enc, self.last_s = self.enc + 1, t_s

    def tick(self, t_s: float) -> None:
        """An ENC_E2E page and a FRAME_TOTALS page made now (``PageKeeper``'s rows)."""
        c = self.counts
        if self.enc > 0:
            last = self.pages[-1] if self.pages else None
            ok = (c[OK]) & 0xFFFF
            ok_u, chain = chained_ok(None if last is None else (last[6], last[7], last[5]), ok,
                                     t_s)
            self.pages.append((self.enc - 1, self.last_s, self.enc, ok, 0, t_s, ok_u, chain,
                               self.raw - 1, self.raw, packed(c[REPEATED], c[CRC],
                                                              c[WRONG_SEQ])))
        rejected = (c[REPEATED] + c[CRC] + c[WRONG_SEQ] + self.other_rejected) & 0xFFFF
        prev = self.totals[-1] if self.totals else None
        breaks = chained_breaks(prev, t_s + 0.001, rejected, self.overflowed & 0xFFFF)
        self.totals.append((t_s + 0.001, rejected, self.overflowed & 0xFFFF, breaks))


def run(events: list[Frame | str]) -> tuple[Seen, Bus]:
    bus = Bus()
    for k, event in enumerate(events):
        t_s = k * CYCLE_S
        if isinstance(event, Frame):
            bus.frame(event, t_s)
        elif event == OTHER:
            bus.other_rejected += 1
        else:
            bus.tick(t_s)
    bus.tick(len(events) * CYCLE_S)
    return seen_of(bus.pages, bus.totals, []), bus


def proven(seen: Seen, first: int, last: int) -> bool:
    """Whether ENC_E2E_OK's count proves the log's frames ``first`` .. ``last`` taken."""
    return any(lo <= first and last <= hi for lo, hi in seen.counted)


def refusing(n: int) -> list[Frame | str]:
    """``n`` encoder frames, every third refused as a delay's reordering makes it."""
    return [Frame(WRONG_SEQ if k % 3 == 2 else OK) for k in range(n)]


BEFORE = [*refusing(6), TICK, *refusing(6), TICK]  # pages before the middle
AFTER = [*refusing(6), TICK, *refusing(6), TICK]


def test_refusals_the_log_holds_prove_the_frames_taken() -> None:
    """The premise: every frame logged, a frame refused every three: the proof holds across
    the middle, where gapseen's proofs by OK and by LOST (quiet windows only) cannot."""
    seen, _ = run([*BEFORE, *refusing(9), *AFTER])
    assert proven(seen, 8, 14)
    assert not seen.missed  # LOST proves nothing here


def test_a_refused_frame_the_log_lacks_blocks_it() -> None:
    """ENC_E2E_OK alone grows as the log's frames: only the refusals' count tells."""
    middle = [*refusing(4), Frame(WRONG_SEQ, logged=False), *refusing(4)]
    seen, _ = run([*BEFORE, *middle, *AFTER])
    assert not proven(seen, 8, 14)


def test_an_accepted_frame_the_log_lacks_blocks_it() -> None:
    middle = [*refusing(4), Frame(OK, logged=False), *refusing(4)]
    assert not proven(run([*BEFORE, *middle, *AFTER])[0], 8, 14)


def test_a_dropped_frame_blocks_it() -> None:
    """A frame logged the mailbox dropped and one the log lacks the firmware took: the counts
    balance; OVERFLOWED_FRAMES alone tells."""
    middle = [*refusing(4), Frame(OK, dropped=True), Frame(OK, logged=False), *refusing(3)]
    assert not proven(run([*BEFORE, *middle, *AFTER])[0], 8, 14)


def test_256_refusals_the_log_lacks_block_it() -> None:
    """256 frames of bad CRC the log lacks (a forger's flood): the u8 count wraps to where it
    was; REJECTED_FRAMES grew by 256, beyond what the u8 counts can tell."""
    middle = [*refusing(4), *[Frame(CRC, logged=False)] * 256, *refusing(5)]
    assert not proven(run([*BEFORE, *middle, *AFTER])[0], 8, 14)


def test_an_other_refusal_does_not_block_it() -> None:
    """A refusal of another receiver (a set-pose of a wrong sequence) changes no encoder frame:
    REJECTED_FRAMES need not equal the encoder refusals."""
    assert proven(run([*BEFORE, *refusing(4), OTHER, *refusing(5), *AFTER])[0], 8, 14)


frames = st.builds(Frame, st.sampled_from([OK, OK, OK, REPEATED, CRC, WRONG_SEQ]),
                   st.integers(0, 19).map(lambda k: k > 0),
                   st.integers(0, 19).map(lambda k: k == 0))


@settings(max_examples=300, deadline=None)
@given(st.lists(st.one_of(frames, st.sampled_from([TICK, TICK, OTHER])), max_size=80))
def test_what_it_proves_the_firmware_took_is_the_log_s(events: list[Frame | str]) -> None:
    """Any bus: over a stretch proven, the firmware received no frame the log lacks and
    dropped none (the host's accepted frames ``first`` .. ``last``)."""
    seen, bus = run(events)
    for first, last in seen.counted:
        inside = [f for f, before in bus.frames if first < before <= last]
        assert all(f.logged and not f.dropped for f in inside), (first, last)


def test_refusals_of_other_receivers_past_255_do_not_block_it() -> None:
    """REJECTED_FRAMES grew by 270 between the pages (220 refusals of other receivers, 50 of
    the encoder's E2E check), the u8 counts by 50: 256 more in any of them would make 306 >
    270, so none wrapped and the proof holds (it asked REJECTED to grow by at most 255: the
    bus-off of pmir straight seed 411 kept gapbound's 1886 mm, r = 274, g = 185)."""
    middle = [*refusing(4), *[OTHER] * 220, *refusing(146)]
    seen, bus = run([*BEFORE, *middle, *AFTER])
    grew = bus.totals[-1][1] - bus.totals[0][1]
    assert grew > 255, grew
    assert proven(seen, 8, 100)


def test_a_wrap_hidden_among_other_refusals_blocks_it() -> None:
    """256 bad-CRC frames the log lacks with 10 other refusals: the u8 counts show 0, REJECTED
    266 - 0 >= 256, so a wrap cannot be ruled out."""
    middle = [*refusing(4), *[OTHER] * 10, *[Frame(CRC, logged=False)] * 256, *refusing(5)]
    assert not proven(run([*BEFORE, *middle, *AFTER])[0], 8, 14)


CALM: list[Frame | str] = [*[Frame()] * 6, TICK, *[Frame()] * 6, TICK]  # nothing refused


def test_a_frame_the_host_took_and_the_firmware_refused_is_counted_skipped() -> None:
    """The firmware refused one frame the host took (REPEATED: kobuki seed 24's bus-off), and
    received no frame the log lacks: not proven taken exactly, but one frame skipped over the
    middle (``Seen.skips``, ``host.judge.gapskips``)."""
    middle = [*[Frame()] * 4, Frame(REPEATED, host_took=True), *[Frame()] * 4]
    seen, _ = run([*CALM, *middle, *CALM])
    assert not proven(seen, 12, 20)
    assert any(lo <= 12 and hi >= 20 and m == 1 for lo, hi, m in seen.skips), seen.skips
    assert seen.skipped(16) == 1
    assert seen.skipped(13) is None  # the frame before it less one lies beyond the run


def test_a_frame_the_log_lacks_leaves_no_skips() -> None:
    middle = [*[Frame()] * 3, Frame(REPEATED, host_took=True), Frame(OK, logged=False),
              *[Frame()] * 4]
    seen, _ = run([*CALM, *middle, *CALM])
    assert not seen.skips


def test_a_refused_frame_the_host_refused_too_leaves_no_skips() -> None:
    """The log holds a frame both refused: the firmware may have taken another it refused
    (the counts cannot tell which), so no run of the host's frames is proven."""
    middle = [*refusing(4), Frame(REPEATED, host_took=True), *[Frame()] * 4]
    seen, _ = run([*CALM, *middle, *CALM])
    assert not seen.skips


skipping = st.builds(Frame, st.sampled_from([OK, OK, OK, REPEATED, CRC, WRONG_SEQ]),
                     st.integers(0, 19).map(lambda k: k > 0),
                     st.integers(0, 19).map(lambda k: k == 0),
                     st.integers(0, 5).map(lambda k: k == 0))


@settings(max_examples=300, deadline=None)
@given(st.lists(st.one_of(skipping, st.sampled_from([TICK, TICK, OTHER])), max_size=80))
def test_over_a_run_with_skips_the_firmware_took_only_the_host_s_frames(
        events: list[Frame | str]) -> None:
    """Any bus: over a run of ``skips`` (first, last, m), every frame was logged and none
    dropped, and the firmware refused at most m of the frames the host took."""
    seen, bus = run(events)
    for first, last, m in seen.skips:
        inside = [f for f, before in bus.frames if first < before <= last]
        assert all(f.logged and not f.dropped for f in inside), (first, last)
        refused = [f for f in inside if f.status != OK]
        assert all(f.host_took for f in refused), (first, last)
        assert len(refused) <= m, (first, last, m)


def test_as_many_frames_taken_but_others_block_it() -> None:
    """ENC_E2E_OK's growth equals the host's, but the host counted a whole COUNTER cycle more
    lost from frame 10 on (it took a frame the firmware refused, and refused one it took:
    kobuki 444 after its bus-off): the firmware's ENC_E2E_LOST did not grow so, not the same
    frames, no proof across frame 10; the same sums keep the proof."""
    seen, bus = run([*BEFORE, *refusing(9), *AFTER])
    assert proven(seen, 8, 14)
    same = np.zeros(bus.enc, dtype=np.int64)
    assert proven(seen_of(bus.pages, bus.totals, [], None, same), 8, 14)
    other = np.where(np.arange(bus.enc) >= 10, 16, 0).astype(np.int64)
    assert not proven(seen_of(bus.pages, bus.totals, [], None, other), 8, 14)
