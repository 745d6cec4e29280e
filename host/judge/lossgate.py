"""The encoder counts the firmware integrates, for the loss allowance (``host.judge.losses``):
a frame of the log whose counts lie beyond the firmware's plausibility bound from the last
frame it accepted (a babbler's random payload that passed Profile 2's CRC, about one in 256) is
refused on board (firmware/ecu.py, IMPLAUSIBLE_STEP, not integrated): the firmware's position
goes on from the last accepted frame's counts. Merging steps across such a frame costs what
merging the real frames around it costs, not what the forged counts would (metres of wheel
travel in one period: a merge error of millimetres per lost frame, 10 000 times the real one).

Here a refused frame takes the counts of the last accepted frame (a step of 0 into it, the
next accepted frame's step from the last accepted one), as ``reference_path.firmware_steps``
takes it. The bound is ``gapbound.period_bounds`` (one count more than the firmware's, so a
frame the firmware may accept is never refused here) over the sender's periods between the
frames. A frame whose counts set wire bits above a 16-bit counter's width (``beyond_width``) is
refused outright, as the firmware refuses it, and is no part of a refusal run.
``RESYNC_FRAMES`` refusals in a row: the counters restarted (the firmware re-primes);
the gate accepts the frame raw, and the allowance across it keeps the raw counts' (wide, never
short) merge error."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from odocan.firmware.encoders import RESYNC_FRAMES
from odocan.host.judge.reference import wrap_delta
from odocan.host.judge.samples import WIRE_COUNTER_BITS, IntArray

WIRE_MASK = (1 << WIRE_COUNTER_BITS) - 1  # the wire's 24 count bits


def beyond_width(left: IntArray, right: IntArray, bits: int) -> npt.NDArray[np.bool_]:
    """Per frame: its wire counts set bits at or above ``bits`` (the wire counter width, 16 or
    24), which no counter of that width sends: the firmware refuses the frame before any other
    rule (firmware/encoders.py ``_refuse_unused_bits``; a forged payload that passed Profile 2's
    CRC, 255 in 256 of them on a 16-bit robot). All False for 24 bits."""
    found: npt.NDArray[np.bool_] = np.zeros(len(left), dtype=np.bool_)
    if bits < WIRE_COUNTER_BITS:
        found = (((np.asarray(left) | np.asarray(right)) & WIRE_MASK) >> bits) != 0
    return found


@dataclass(frozen=True)
class Gate:
    """The last frame the firmware accepted (wire counts, sender sequence number) and how many
    frames it refused since: the gate's state from one chunk of frames to the next."""

    left: int
    right: int
    seq: int
    refused: int = 0


def gated_counts(
    left: IntArray, right: IntArray, seq: IntArray, bounds: tuple[int, int], bits: int,
    gate: Gate | None = None,
) -> tuple[IntArray, IntArray, Gate | None]:
    """The wire counts of frames ``left``, ``right`` (sender sequence ``seq``) with each frame
    the firmware refuses replaced by the last accepted frame's (module docstring); ``bounds``:
    the counts per wheel per period; ``bits``: the wire counter width; ``gate``: the state after
    the frames before (None: the first frame is accepted). Returns the counts and the state
    after the last frame (None without a frame). Vectorised; a short loop runs only from each
    step beyond the bound on."""
    if len(left) == 0:
        return left, right, gate
    if gate is None:
        gate = Gate(int(left[0]), int(right[0]), int(seq[0]))
    all_l = np.concatenate(([gate.left], left)).astype(np.int64)
    all_r = np.concatenate(([gate.right], right)).astype(np.int64)
    all_s = np.concatenate(([gate.seq], seq)).astype(np.int64)
    periods = np.maximum(np.diff(all_s), 1)
    foreign = beyond_width(all_l, all_r, bits)  # refused outright, no part of a run
    bad = ((np.abs(wrap_delta(np.diff(all_l), bits)) > periods * bounds[0])
           | (np.abs(wrap_delta(np.diff(all_r), bits)) > periods * bounds[1]) | foreign[1:])
    if gate.refused:
        bad[0] = True  # within a refusal run: the loop decides from the first frame
    if not bad.any():
        return left, right, Gate(int(left[-1]), int(right[-1]), int(seq[-1]))
    out_l, out_r = all_l.copy(), all_r.copy()
    refused = gate.refused
    acc_l, acc_r, acc_s = gate.left, gate.right, gate.seq  # the last accepted frame's
    i = int(np.flatnonzero(bad)[0]) + 1
    while i < len(all_l):
        if refused == 0 and not foreign[i - 1]:  # the frames up to i - 1 accepted: i - 1 the last
            acc_l, acc_r, acc_s = int(all_l[i - 1]), int(all_r[i - 1]), int(all_s[i - 1])
        if foreign[i]:
            out_l[i], out_r[i] = acc_l, acc_r
            i += 1
            continue
        span = max(int(all_s[i]) - acc_s, 1)
        if (abs(int(wrap_delta(int(all_l[i]) - acc_l, bits))) <= span * bounds[0]
                and abs(int(wrap_delta(int(all_r[i]) - acc_r, bits))) <= span * bounds[1]) \
                or refused + 1 >= RESYNC_FRAMES:
            refused = 0
            later = np.flatnonzero(bad[i:])  # bad[k]: the step into element k + 1
            i = i + int(later[0]) + 1 if len(later) else len(all_l)
            continue
        refused += 1
        out_l[i], out_r[i] = acc_l, acc_r
        i += 1
    if refused == 0 and not foreign[-1]:  # the last frame accepted
        acc_l, acc_r, acc_s = int(all_l[-1]), int(all_r[-1]), int(all_s[-1])
    return out_l[1:], out_r[1:], Gate(acc_l, acc_r, acc_s, refused)
