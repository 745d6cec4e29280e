"""Which pose halves may name another encoder frame than the one their ENC_COUNTER is matched to
(``host.judge.resent``): the sender's 4-bit COUNTER comes round every 16 frames, so a pose sent
long after the frame it was matched to may name a later frame with the same COUNTER that the
host refused and the firmware took (after the firmware's E2E lock-out, with frames held back on
the bus: `--faults delay=0.1:15,seed=2`, 10 s, sent 12 poses naming COUNTER 10 over 0.22 s, the
last four after the next frame with COUNTER 10, which the firmware took and the host did not).
Such a half is no resend: judging it as one blames a correct firmware (6.4 mm / 606 mrad there).

A half may alias when a frame with the matched frame's COUNTER (any on the bus: refused ones
too) came between the matched frame and the half in the log (the bus order is exact in a
capture), or when ``ALIAS_CYCLES`` encoder cycles of bus time passed since the matched frame
(frames the log lacks: a recorder's gap). A correct firmware's real resends come in the ticks
right after the frame (it ticks without a new one), well inside both."""

from __future__ import annotations

from typing import TYPE_CHECKING, overload

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP, ENC_COUNTER_MASK
from odocan.host.protocol.decode import BulkDecoder, DecodeError

if TYPE_CHECKING:
    from odocan.host.judge.samples import Encoders

ALIAS_CYCLES = 12  # 16 frames a COUNTER round, less 4 cycles a frame may be held back
COUNTER_MODULO = ENC_COUNTER_LAP  # 16: the E2E COUNTER of WHEEL_ENCODERS (byte 1, low nibble)


@overload
def aged_past_alias(since_s: float, cycle_s: float) -> bool: ...
@overload
def aged_past_alias(since_s: npt.NDArray[np.float64], cycle_s: float) -> npt.NDArray[np.bool_]: ...
def aged_past_alias(since_s: float | npt.NDArray[np.float64], cycle_s: float
                    ) -> bool | npt.NDArray[np.bool_]:
    """The time rule (module docstring), the one every judge applies: a half heard ``since_s``
    after the frame it was matched to may name a later frame of that COUNTER when
    ``ALIAS_CYCLES`` encoder cycles of ``cycle_s`` passed, or when the time is unknown (NaN)."""
    aged = np.logical_not(np.less(since_s, ALIAS_CYCLES * cycle_s))
    return bool(aged) if np.ndim(aged) == 0 else aged


def may_alias(frames: FrameArrays, decoder: BulkDecoder, enc: Encoders,
              rows: npt.NDArray[np.int64], named: npt.NDArray[np.int64]
              ) -> npt.NDArray[np.bool_]:
    """Per pose half at log position ``rows`` matched to encoder frame ``named`` (an index into
    ``enc``; -1: none), whether it may name another frame (module docstring)."""
    out = np.ones(len(rows), dtype=bool)
    hit = named >= 0
    if enc.cycle_s is None or not hit.any():
        return out
    try:
        every = np.asarray(decoder.select(frames, "WHEEL_ENCODERS"), dtype=np.int64)
    except (DecodeError, KeyError):
        return out
    at = named[hit]
    since_s = frames.timestamp_s[rows[hit]] - enc.timestamp_s[at]
    alias = aged_past_alias(since_s, enc.cycle_s)
    counters = frames.data[every, 1] & ENC_COUNTER_MASK
    for c in range(COUNTER_MODULO):
        mine = enc.counter[at] == c
        if not mine.any():
            continue
        same = every[counters == c]
        k = np.searchsorted(same, enc.index[at][mine], side="right")
        nxt = np.where(k < len(same), same[np.minimum(k, len(same) - 1)], np.iinfo(np.int64).max)
        alias[mine] |= nxt < rows[hit][mine]
    out[hit] = alias
    return out
