"""A twist the bus held back is no DISTANCE fall (``distfall``, issue #11), for every judge.

One life's DISTANCE only grows, so a twist below the one heard before it tells a new firmware
(``distfall``), but only when the twists come in the order they were sent: a bus that holds a
frame back lets later ones overtake it, and the late one reads below them. Kobuki random 695,
``reboot=0.5:0.3,delay=0.1:150``: the twist of COUNTER 1 sent at 1.461 s, heard at 1.611 s after
COUNTER 8 (DISTANCE 0.139 m after 0.164 m), 10 ms after the summary of COUNTER 0 that laps every
0.8 s of UPTIME 0: told a second reboot at 1.601 s by every judge (``bootticks.boot_ahead``'s
``fell``). A twist that fills a hole of its sender's sequence (``liveheldpose.PoseOrder``, the
poses' rule: ODOM_TWIST shares their cycle and 4-bit COUNTER) within a sequence unbroken since
is such a late one: its fall says nothing. Read on the ``WINDOW`` twists heard before it (the
in-order frames ``PoseOrder`` keeps), the same in the whole log, a stream (carried across
chunks) and live (``fell_unheld`` on the twists the watch keeps).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.distfall import TWIST_MESSAGE, DistanceField, Falls, fell_within
from odocan.host.judge.liveheldpose import PoseOrder
from odocan.host.judge.livelatestatus import RECENT
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e import crc8h2f_p02, e2e_messages

WINDOW = RECENT + 1  # the twists read before one that fell: ``PoseOrder``'s in-order frames
Heard = tuple[tuple[float, int], ...]  # (bus time s, E2E COUNTER) of twists, in bus order


def held_last(heard: Sequence[tuple[float, int]]) -> bool:
    """Whether the last twist of ``heard`` (bus time, COUNTER; in order, up to ``WINDOW`` of
    them before it) was held back within its sender's unbroken sequence (``PoseOrder.hear``)."""
    order, held = PoseOrder(), False
    for t_s, counter in heard[-WINDOW - 1:]:
        held = order.hear(counter, t_s)
    return held


def twist_rows(frames: FrameArrays, decoder: BulkDecoder
               ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """Bus times and E2E COUNTERs of the ODOM_TWIST frames of ``frames`` whose CRC holds."""
    try:
        message = decoder.message(TWIST_MESSAGE)
        rows = np.asarray(decoder.select(frames, TWIST_MESSAGE), dtype=np.int64)
    except (DecodeError, KeyError):
        return np.zeros(0, np.float64), np.zeros(0, np.int64)
    data = frames.data[rows]
    counter = (data[:, 1] & ENC_COUNTER_MASK).astype(np.int64)
    config = e2e_messages(decoder.db).get(message.frame_id)
    good = np.ones(len(rows), dtype=bool)
    if config is not None and config.data_ids is not None and len(rows):
        good = crc8h2f_p02(data, np.array(config.data_ids, dtype=np.uint8)[counter]) == data[:, 0]
    return frames.timestamp_s[rows][good].astype(np.float64), counter[good]


def unheld_falls(frames: FrameArrays, decoder: BulkDecoder, falls: Falls,
                 carried: Heard = ()) -> tuple[Falls, Heard]:
    """``falls`` (``distfall.fall_times`` of ``frames``) less those of twists held back
    (``held_last``; ``carried``: the twists heard before ``frames``, a stream's), and the last
    ``WINDOW`` twists heard (the next chunk's ``carried``)."""
    t_s, counters = twist_rows(frames, decoder)
    heard = [*carried, *zip(t_s.tolist(), counters.tolist(), strict=True)]
    keep = np.ones(len(falls.times_s), dtype=bool)
    first = len(carried)
    for k, (fall_s, counter) in enumerate(zip(falls.times_s.tolist(), falls.counters.tolist(),
                                              strict=True)):
        at = first + int(np.searchsorted(t_s, fall_s))
        while at < len(heard) - 1 and heard[at][1] != counter and heard[at][0] == fall_s:
            at += 1
        keep[k] = not held_last(heard[max(at - WINDOW, 0):at + 1])
    kept = Falls(falls.times_s[keep], falls.counters[keep], falls.befores_s[keep])
    return kept, tuple(heard[-WINDOW:])


def fell_unheld(field: DistanceField | None, heard: Iterable[tuple[float, bytes]],
                tied: Callable[[float, int, float], bool], small: int) -> bool:
    """``distfall.fell_within`` live (the twists kept, bus time and bytes, in order) where the
    twist that fell was not held back (``held_last`` of those heard up to it)."""
    if field is None:
        return False
    kept = list(heard)
    order = [(t_s, c) for t_s, data in kept if (c := field.counter(data)) is not None]

    def unheld(t_s: float, counter: int, before_s: float) -> bool:
        at = next((k for k, (t, c) in enumerate(order) if t == t_s and c == counter), None)
        return (tied(t_s, counter, before_s)
                and (at is None or not held_last(order[max(at - WINDOW, 0):at + 1])))

    return fell_within(field, kept, unheld, small)
