"""The encoder frame a queued frame names (``samples.match_encoder``'s last step): a frame that
waited in its sender's transmit buffer and came out in a burst (``senderseq.queued_frames``) is
resolved from when its sender made it, not from when the bus let it out (host.judge.analysis
docstring, step 3). Moved out of ``samples`` (near its 500 lines) unchanged."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from odocan.host.judge.holechain import hole_between
from odocan.host.judge.senderseq import queued_frames
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP as LAP
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK

if TYPE_CHECKING:
    from odocan.host.judge.samples import Encoders, FloatArray, IntArray


def queued_names(
    named: IntArray, enc: Encoders, index: IntArray, enc_counter: IntArray,
    own_counter: IntArray, timestamp_s: FloatArray,
) -> IntArray:
    """``named`` with each queued frame (``queued_frames``) resolved from when its sender made
    it, not from when the bus let it out (host.judge.analysis docstring, step 3).

    A queued frame was made long before it reached the bus, so the latest encoder frame before
    it on the bus says nothing of what its sender had. Its sender makes one every send period
    (the median spacing of the frames, 20 ms for a pose): counted on from the last frame before
    the burst that was not queued (sent when made), without a loss between (own COUNTER + 1
    each, and no hole of the log a COUNTER lap long between: ``holechain.hole_between``), the
    k-th queued frame was made ``k`` send periods later. It names the latest encoder frame of
    its ENC_COUNTER that was on the bus by then, not before the frame its predecessor
    named (a firmware names frames in increasing order) and accepted in the log before it.
    A queued frame without such a chain names none (it is left out, not guessed)."""
    assert enc.cycle_s is not None
    queued = queued_frames(timestamp_s, enc.cycle_s)
    if not queued.any():
        return named
    send_s = float(np.median(np.diff(timestamp_s)))
    named = named.copy()
    made_s = np.nan  # when the previous frame was made (bus time s)
    for k in range(len(named)):
        if not queued[k]:
            made_s = float(timestamp_s[k])
            continue
        chained = (k > 0 and named[k - 1] >= 0
                   and (int(own_counter[k] - own_counter[k - 1]) & ENC_COUNTER_MASK) == 1
                   and not hole_between(enc.index, enc.seq, int(index[k - 1]), int(index[k])))
        made_s = made_s + send_s if chained else np.nan
        named[k] = named_by(enc, int(named[k - 1]), int(enc_counter[k]), made_s, int(index[k]),
                             send_s, bool(enc_counter[k] == enc_counter[k - 1]))
    return named


def named_by(
    enc: Encoders, floor: int, enc_counter: int, made_s: float, index: int, send_s: float,
    repeat: bool = False,
) -> int:
    """The latest accepted encoder frame at or after ``floor`` with COUNTER ``enc_counter``, on
    the bus by ``made_s`` and before frame ``index`` of the log; -1 when none (or no time), and
    -1 when the name is ambiguous: another accepted frame of that COUNTER (16 before or after
    it, at or after ``floor``, before ``index``) came within half a send period (``send_s``) of
    it on the bus. That happens when the encoder frames came out in a burst too (about 240 us
    apart at 500 kbit/s, 16 of them in 3.8 ms; about 1 ms apart at 125 kbit/s, 16 ms): ``made_s``
    is good to a fraction of a send period, and a firmware whose mailbox overflowed had an
    earlier frame of that COUNTER than the latest on the bus, so time cannot tell which it had.

    -1 too when ``repeat`` (the frame repeats its predecessor's ENC_COUNTER) and a frame of
    that COUNTER 16 periods before it is at or after ``floor`` (the frame the predecessor
    named, which the firmware may still hold): it may have taken none of the frames on the
    bus since, as when its E2E lock-out refuses them (a late frame, then the COUNTER repeated
    16 periods on), and the pose or twist it made then names the older frame. Found on kobuki
    and pmir, seed 10, ``delay=0.1:20``, a capture jittered (seed 0): a twist queued behind the
    next, made while the firmware held a frame and refused the four after it, was named 16
    periods later, where the host's path was 5.8 mm longer: the correct firmware FAILed
    ODOM_TWIST DISTANCE (tests/test_twist_jitter_distance.py)."""
    if np.isnan(made_s):
        return -1
    last = min(int(np.searchsorted(enc.timestamp_s, made_s, side="right")),
               int(np.searchsorted(enc.index, index))) - 1
    if last < floor:
        return -1
    target = int(enc.seq[last]) - ((int(enc.counter[last]) - enc_counter) & ENC_COUNTER_MASK)
    found = int(np.searchsorted(enc.seq, target))
    if target < enc.seq[floor] or found >= len(enc.seq) or enc.seq[found] != target:
        return -1
    if repeat and target - LAP >= enc.seq[floor]:  # it may still hold the floor
        return -1
    for other in (target - LAP, target + LAP):
        j = int(np.searchsorted(enc.seq, other))
        if (j < len(enc.seq) and enc.seq[j] == other and j >= floor and enc.index[j] < index
                and abs(float(enc.timestamp_s[j] - enc.timestamp_s[found])) < 0.5 * send_s):
            return -1
    return found
