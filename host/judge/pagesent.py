"""When a rebooted firmware's first page of WHEEL_ENCODERS E2E counts was sent, not heard: the
place ``primed.counted_start`` counts back from (issue #11: a FAIL must never blame a correct
firmware).

The page names the frame the firmware primed on: ENC_E2E_OK + ENC_E2E_LOST - 1 COUNTER steps
back from the latest encoder frame it took before it sent the page. Counted from where the page
was heard, a page the bus held back counts from a later frame and names one as late. Kobuki
figure8 672, 9 s, ``reboot=1.8:0.2,stall=5.6:0.2,delay=0.3:55``: the reboot at 2.0 s primed on
the encoder frame of 2.020 s; its first count page (OK 7, LOST 2), sent at 2.101 s with its
summary, both held back 55 ms, was heard at 2.156 s, in order (no later frame of ODOM_STATUS
came before it: ``latenames`` has nothing to read). Counted from there the life started at the
frame of 2.070 s, its first poses were judged as the old life's, and the correct firmware
FAILed by 634.4 mm (DISTANCE 19.5 mm).

The firmware sends ODOM_STATUS in pairs, the summary then a rotating page, once per status
cycle of its ticks (firmware/reports.py), never sooner: a frame of the next tick's pair (E2E
COUNTER one or two steps on) heard at t was sent a cycle or more after the page, so the page
was sent at ``t - STATUS_CYCLE_S`` or before (an upper bound, whatever held either back or
however long the firmware stalled between). The page is counted from the earlier of that and
its own stamp: from the latest encoder frame stamped before it. Only the next frame heard after
the page counts (its CRC holding), and not a power-up tick's (COUNTER 0 or 1): a firmware
rebooted right after the page restarts its sequence, and its first pair is no cadence of the
page's. On a log without held-back status frames nothing moves: the next pair comes a cycle
after the page. A page not held back (``pagetick.page_held_back``) whose tick's pose was heard
right before it counts from the frame that pose names (``pagetick``): a frame heard between the
firmware's mailbox read and its page is not one it took.

One rule for the whole-log judge (``reboots.page_counted_start``, the replay's first power-up),
the streamed (``stream_lives``) and the live judge (``livestart.Lives.on_counts``).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.bootnamed import PoseRows, pose_enc_rows
from odocan.host.judge.bootticks import status_rows
from odocan.host.judge.gapseen import crc_holds
from odocan.host.judge.pagetick import named_after, page_held_back, pages_named_after
from odocan.host.judge.samples import ENC_E2E_PAGE
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK, STATUS_CYCLE_S
from odocan.host.protocol.decode import BulkDecoder, DecodeError

NEXT_TICK_STEPS = (1, 2)  # E2E COUNTER steps from a page to the next tick's summary and page
POWER_UP_COUNTERS = (0, 1)  # a firmware's first tick's pair: another sequence begins


def sent_s(page: tuple[float, int], following: tuple[float, int] | None) -> float:
    """The latest bus time the page heard at ``page`` (bus time, E2E COUNTER) can have been
    sent at, from the next ODOM_STATUS frame heard after it (``following``: bus time and
    COUNTER, CRC holding; None: none heard): module docstring."""
    heard_s, counter = page
    if following is None or following[1] in POWER_UP_COUNTERS:
        return heard_s
    step = (following[1] - counter) & ENC_COUNTER_MASK
    if step not in NEXT_TICK_STEPS:
        return heard_s
    return min(heard_s, following[0] - STATUS_CYCLE_S)


def counted_from(
    page: int, page_sent_s: float, encoders: tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]
) -> int:
    """The log position ``counted_start`` counts back from for a page heard at ``page`` and sent
    at ``page_sent_s``: the first of the encoder frames (``encoders``: positions, bus times, in
    bus order) before the page stamped at or after its send, so that the latest before it is the
    latest the firmware could have taken; ``page`` when none is."""
    at, t_s = encoders
    k = int(np.searchsorted(at, page))
    j = k
    while j > 0 and t_s[j - 1] >= page_sent_s:
        j -= 1
    return page if j == k else int(at[j])


def pages_counted_from(
    frames: FrameArrays,
    decoder: BulkDecoder,
    pages: npt.NDArray[np.int64],
    taken: tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]],
) -> npt.NDArray[np.int64]:
    """The log position each count page at log positions ``pages`` (CRC holding) of a whole
    log counts back from: from the frame its tick's pose names unless it was held back
    (``pagetick``; ``taken``: the positions and COUNTERs of the encoder frames the firmware
    takes), else ``counted_from`` its send, its next ODOM_STATUS frame heard (CRC holding) read
    by ``sent_s``."""
    where, t_s, counter = status_rows(frames, decoder)
    out = np.asarray(pages, dtype=np.int64).copy()
    row = np.searchsorted(where, out)
    ok = row < len(where)
    ok[ok] = where[row[ok]] == out[ok]
    row = row[ok]
    heard_s, sent = t_s[row], t_s[row].copy()
    nxt = np.minimum(row + 1, len(where) - 1)
    step = (counter[nxt] - counter[row]) & ENC_COUNTER_MASK
    cadence = (row + 1 < len(where)) & np.isin(step, NEXT_TICK_STEPS) & ~np.isin(
        counter[nxt], POWER_UP_COUNTERS)
    sent[cadence] = np.minimum(heard_s[cadence], t_s[nxt[cadence]] - STATUS_CYCLE_S)
    named = pages_named_after(out[ok], heard_s, pose_enc_rows(frames, decoder), taken)
    by_tick = (named >= 0) & ~page_held_back(heard_s, sent)
    counted = out[ok]
    counted[by_tick] = named[by_tick]
    moved = np.flatnonzero(~by_tick & (sent < heard_s))
    if len(moved):
        enc = decoder.select(frames, "WHEEL_ENCODERS").astype(np.int64)
        encoders = (enc, np.asarray(frames.timestamp_s[enc], dtype=np.float64))
        for k in moved.tolist():
            counted[k] = counted_from(int(counted[k]), float(sent[k]), encoders)
    out[ok] = counted
    return out


def encoder_count_pages(
    frames: FrameArrays, decoder: BulkDecoder
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Positions, ENC_E2E_OK and ENC_E2E_LOST (0 where the DBC has none) of the ODOM_STATUS
    pages of WHEEL_ENCODERS E2E counts whose CRC holds (empty when the log or the DBC has
    none); ``reboots`` re-exports it."""
    none = (np.zeros(0, dtype=np.int64),) * 3
    try:
        page = decoder.decode_page(frames, "ODOM_STATUS", ENC_E2E_PAGE)
    except DecodeError:
        return none
    if "ENC_E2E_OK" not in page:
        return none
    good = crc_holds(frames, decoder, page["index"])
    lost = page.get("ENC_E2E_LOST", np.zeros(len(good), dtype=np.int64))
    return (
        page["index"][good].astype(np.int64),
        page["ENC_E2E_OK"][good].astype(np.int64),
        lost[good].astype(np.int64),
    )


Counts = tuple[int, int, int]  # ENC_E2E_OK, ENC_E2E_LOST, the position counted from


Waiting = tuple[int, int, int, float, int, int | None]  # position, OK, LOST, t, COUNTER, named


class StreamPages:
    """The count pages of a log chunk by chunk (``stream_lives``), each as (position heard,
    ``Counts``): ``pages_counted_from`` of the whole log. A page whose next ODOM_STATUS frame
    is not in its chunk waits for the next chunk (``finish``: the log's end, counted from where
    its tick's pose names or it was heard)."""

    def __init__(self, decoder: BulkDecoder) -> None:
        self._decoder = decoder
        self._waiting: list[Waiting] = []

    def feed(
        self,
        chunk: FrameArrays,
        offset: int,
        encoders: tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]],
        told_by: tuple[PoseRows, tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]],
    ) -> list[tuple[int, Counts]]:
        """The pages told by ``chunk`` (at log position ``offset``): those waiting and the
        chunk's own whose next ODOM_STATUS frame it holds; ``encoders``: the positions and bus
        times of the encoder frames carried, ``told_by``: the poses (``pose_enc_rows``) and the
        positions and COUNTERs of the encoder frames taken carried, this chunk's included."""
        where, t_s, counter = status_rows(chunk, self._decoder)
        rows = [
            (int(p) + offset, float(t), int(c))
            for p, t, c in zip(where.tolist(), t_s.tolist(), counter.tolist(), strict=True)
        ]
        pages = self._waiting + [
            (*page, named_after((page[0], page[3]), *told_by))
            for page in _chunk_pages(chunk, self._decoder, offset, rows)
        ]
        positions = np.array([position for position, _, _ in rows], dtype=np.int64)
        told, self._waiting = [], []
        for page in pages:
            k = int(np.searchsorted(positions, page[0], side="right"))
            if k == len(positions):
                self._waiting.append(page)
                continue
            sent = sent_s((page[3], page[4]), rows[k][1:])
            named = page[5]
            if named is None or page_held_back(page[3], sent):
                named = counted_from(page[0], sent, encoders) if sent < page[3] else page[0]
            told.append((page[0], (page[1], page[2], named)))
        return told

    def finish(self) -> list[tuple[int, Counts]]:
        """The pages still waiting at the log's end: no frame after them tells their send."""
        told = [(p[0], (p[1], p[2], p[0] if p[5] is None else p[5])) for p in self._waiting]
        self._waiting = []
        return told


def _chunk_pages(
    chunk: FrameArrays, decoder: BulkDecoder, offset: int, rows: list[tuple[int, float, int]]
) -> list[tuple[int, int, int, float, int]]:
    """The chunk's count pages whose CRC holds (``rows``: its ODOM_STATUS frames whose CRC
    holds, at their log positions): position, ENC_E2E_OK, ENC_E2E_LOST, bus time, COUNTER."""
    try:
        page = decoder.decode_page(chunk, "ODOM_STATUS", ENC_E2E_PAGE)
    except (DecodeError, KeyError):
        return []
    if "ENC_E2E_OK" not in page or len(page["index"]) == 0:
        return []
    good = crc_holds(chunk, decoder, page["index"])
    lost = page.get("ENC_E2E_LOST", np.zeros(len(good), dtype=np.int64))
    heard = {position: (t, c) for position, t, c in rows}
    return [
        (int(p) + offset, int(ok), int(n), *heard[int(p) + offset])
        for p, ok, n in zip(
            page["index"][good].tolist(),
            page["ENC_E2E_OK"][good].tolist(),
            lost[good].tolist(),
            strict=True,
        )
    ]
