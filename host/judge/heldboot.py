"""A reboot's boot summary the bus held back behind its own tick's next ODOM_STATUS frame, for
``host.judge.reboots`` and ``host.judge.stream_lives`` (issue #11).

A firmware's power-up tick sends its summary (UPTIME 0, E2E COUNTER 0) and then a rotating page
(COUNTER 1, firmware/reports.py). A delaying bus may hold the summary back and let the page out
first: the summary is then stamped up to ``BOOT_WINDOW_S`` after its tick, and the summary's rule
(``reboots.summary_start``: INIT, the first encoder frame after the summary; else the latest
before it) named a frame that late. Kobuki figure8 410, 14 s, ``reboot=3:0.5,stall=8:0.4,
delay=0.3:55``: the summary (INIT) held 55 ms, stamped 3.556 s after its page (3.501 s); the
new firmware primed on the frame heard at 3.515 s, the life was started at 3.565 s, its first
twists (DISTANCE 0 and 8 mm) fell in the old life, which FAILed a correct firmware by DISTANCE
1339 mm. Its first count page, sent 100 ms on and held back too, counted back from the latest
frame heard before it, names a frame late alike, so it does not override this rule.

Told when the ODOM_STATUS frame heard right before the summary (its CRC holding) reads
COUNTER 1, the summary COUNTER 0, and it came less than ``BOOT_WINDOW_S`` before the summary:
the tick was heard at that frame; unless the frame heard before that page reads COUNTER 0 less
than two status cycles (``OLD_SEQUENCE_S``) before it: the page may then be an old firmware's,
continuing its sequence (a reset right after it: ``tests/test_analysis_reboot.py``'s campaign,
an old page of COUNTER 1 74 ms before an INIT summary, 100 ms after its COUNTER 0, started the
life 8 frames early, and its start was fitted); the summary's own rule stands then. A new
firmware whose old one's last ODOM_STATUS read COUNTER 0 that soon before is not told so.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.bootticks import BOOT_WINDOW_S, status_rows
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK, STATUS_CYCLE_S
from odocan.host.protocol.decode import BulkDecoder

STAMP_S = 1e-6  # a log's stamp resolution (candump's): frames stamped together
TICK_PAGE_COUNTER = 1  # the power-up tick's rotating page: sent right after its summary
OLD_SEQUENCE_S = 2 * STATUS_CYCLE_S  # a page this soon after a COUNTER 0 continues its sequence


def summary_start(position: int, uptime_s: int, state: str, encoders: npt.NDArray[np.intp]) -> int:
    """Where the life whose boot summary is at ``position`` starts: at the encoder frame it
    primed on in its first tick (UPTIME 0, not INIT: the latest before the summary, which its
    first pose frames precede too), else at the summary."""
    earlier = encoders[encoders < position]
    if uptime_s == 0 and state != "INIT" and len(earlier):
        return int(earlier[-1])
    return position


def held_tick_s(counter: int, t_s: float, before: tuple[tuple[float, int], tuple[float, int]]
                ) -> float | None:
    """The bus time the power-up tick of a boot summary (E2E ``counter``, heard at ``t_s``) was
    heard at, when the bus held the summary back behind that tick's page (``before``: the bus
    time and COUNTER of the last two ODOM_STATUS frames heard before it, the latest first; NaN
    and -1 where none; module docstring); None otherwise."""
    (page_t, page_counter), (prior_t, prior_counter) = before
    if counter != 0 or page_counter != TICK_PAGE_COUNTER or math.isnan(page_t):
        return None
    if prior_counter == 0 and 0.0 <= page_t - prior_t < OLD_SEQUENCE_S:  # the old one's page
        return None
    return page_t if 0.0 <= t_s - page_t < BOOT_WINDOW_S else None


Before = tuple[tuple[float, int], tuple[float, int]]  # ``held_tick_s``' ``before``
NONE_BEFORE: Before = ((math.nan, -1), (math.nan, -1))


def statuses_before(frames: FrameArrays, decoder: BulkDecoder, positions: npt.NDArray[np.int64],
                    carried: Before = NONE_BEFORE) -> tuple[list[Before], Before]:
    """For the frames at ``positions`` (in order) the last two ODOM_STATUS frames before each
    whose CRC holds (``held_tick_s``' ``before``; ``carried``: those before ``frames``, a
    stream's earlier chunks), and those after them all (the next chunk's ``carried``)."""
    where, times, counters = status_rows(frames, decoder)
    t = [carried[1][0], carried[0][0], *times.tolist()]
    c = [carried[1][1], carried[0][1], *counters.tolist()]
    k = (np.searchsorted(where, positions) + 1).tolist()  # the latest before each, in t and c
    out: list[Before] = [((t[i], c[i]), (t[i - 1], c[i - 1])) for i in k]
    return out, ((t[-1], c[-1]), (t[-2], c[-2]))


def held_start(position: int, uptime_s: int, state: str,
               encoders: tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]],
               tick_s: float, counters: npt.NDArray[np.int64] | None = None) -> int:
    """``reboots.summary_start`` of a summary at log ``position`` whose tick was heard at
    ``tick_s`` (``held_tick_s``): UPTIME 0 and not INIT, the latest encoder frame (``encoders``:
    every one on the bus, its position and bus time: the new firmware's E2E check starts afresh
    and takes it whatever the whole log's check said) heard before the tick, of those stamped
    with it the last that check takes (``counters``, their E2E COUNTERs: ``fresh_last``); else
    the first heard after it and before the summary, or the summary itself when none was."""
    at, t = encoders
    if uptime_s == 0 and state != "INIT":
        earlier = np.flatnonzero(t < tick_s)
        if not len(earlier):
            return position
        if counters is None:
            return int(at[earlier[-1]])
        together = earlier[t[earlier] >= t[earlier[-1]] - STAMP_S]
        return int(at[together[fresh_last(counters[together])]])
    later = at[(t > tick_s) & (at < position)]
    return int(later[0]) if len(later) else position


def fresh_last(counters: npt.NDArray[np.int64]) -> int:
    """The index of the last of encoder frames stamped together (E2E ``counters``, bus order) a
    fresh E2E check draining them at once takes: the first, then each a COUNTER step on from the
    last taken (no time passed: its delta window is one step; firmware/e2e.py). Kobuki random
    696 ``reboot=0.5:0.3,delay=0.1:150``: COUNTER 1 sent at 0.65 s and the on-time COUNTER 0,
    both stamped 0.800 s in that order: the new firmware primed on the 1 (its power-up pose
    names it) and refused the 0; the latest, the 0, started the life a frame off its prime, so
    its count page proved no power-up and a power-up pose 10 mm off was fitted (PASS)."""
    taken = 0
    for k in range(1, len(counters)):
        if (int(counters[k]) - int(counters[taken])) & ENC_COUNTER_MASK == 1:
            taken = k
    return taken


def held_ticks(frames: FrameArrays, decoder: BulkDecoder, positions: list[int]
               ) -> list[float | None]:
    """Per boot summary of the whole log at ``positions``: ``held_tick_s`` (None: not held)."""
    befores = statuses_before(frames, decoder, np.array(positions, dtype=np.int64))[0]
    return [held_tick_s(int(frames.data[p, 1]) & ENC_COUNTER_MASK, float(frames.timestamp_s[p]),
                        before) for p, before in zip(positions, befores, strict=True)]
