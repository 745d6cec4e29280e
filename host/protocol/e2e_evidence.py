"""Encoder-frame refusals the capture's timing cannot decide, settled from the firmware's own
evidence on the bus (issue #11: a live capture on a loaded machine FAILed a correct firmware).

A starved recorder (candump or the monitor on a loaded host) holds the frames it hears for up
to a few periods and stamps them in a burst, bus order kept: the stamps of two WHEEL_ENCODERS
frames no longer say how many of the firmware's ticks passed between them, and the host's model
of the firmware's E2E window (``e2e_periods.receive_periods``, which trusts stamps to
``CAPTURE_TOLERANCE_CYCLES``) refused frames the firmware took (a pose naming one was paired
with nothing, the reference split there) or took frames it refused.

Three readings of the stamps per pair of frames: the strict one (``receive_periods``), one
where the first frame's stamp may be up to ``CAPTURE_HOLD_CYCLES`` late (the window wider) and
one where the second's may (narrower). Where the three give one verdict, the timing decides.
Where they differ, the firmware's poses do:

* **taken**: an ODOM_POSE_X or _Y frame's ENC_COUNTER names the encoder frame the firmware
  integrated last before it sent the pose: the latest encoder frame before the pose with that
  COUNTER (the firmware moved on since its previous send of that message, fewer than 16
  encoder frames before: the name is unique).
* **skipped**: a frame on the bus before the firmware's previous send of that message (so in
  its mailbox before this pose's tick) and after the frame this pose names was refused.

Neither: the frame is taken (the host integrates the finer path) and returned as undecided, for
a bounded allowance (the firmware may have taken its step merged with the next one).

The status codes are ``host.protocol.e2e``'s (``_STATUS`` order: ok, oksomelost, repeated,
wrong_sequence, crc_error).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.protocol.e2e_periods import (
    COUNTER_MODULO,
    RECEIVE_LAG_CYCLES,
    receive_periods,
)

# How late a starved recorder may stamp a frame, in periods: held 1..4 periods (the trial's
# lateness reached +3.9), plus the stamp jitter of ``CAPTURE_TOLERANCE_CYCLES``.
CAPTURE_HOLD_CYCLES = 4.5
EVIDENCE_MESSAGES = ("ODOM_POSE_X", "ODOM_POSE_Y")
S_OK, S_LOST, S_REPEATED, S_WRONG, S_CRC = range(5)
_MAX_WINDOW = 15
IntArray = npt.NDArray[np.int64]


@dataclass(frozen=True)
class Evidence:
    """Encoder frames (indices into one message's frames) the firmware's poses prove it took
    or skipped."""

    taken: frozenset[int]
    skipped: frozenset[int]


def narrow_periods(dt_s: npt.NDArray[np.float64], step: IntArray, cycle_s: float,
                   hold_cycles: float = CAPTURE_HOLD_CYCLES) -> IntArray:
    """``receive_periods`` with the second frame's stamp taken late by capture (up to
    ``hold_cycles``): a second frame that looks late adds only the sender's step."""
    x = dt_s / cycle_s
    s = step + COUNTER_MODULO * np.floor((x - step + COUNTER_MODULO // 2) / COUNTER_MODULO)
    e = x - s
    np.copyto(e, np.maximum(e - hold_cycles, 0.0), where=e > 0)
    late = np.maximum(np.ceil(np.abs(e) - RECEIVE_LAG_CYCLES), 0.0)
    periods = np.maximum(s + np.sign(e) * late, 0.0)
    result: IntArray = periods.astype(np.int64)
    return result


def readings(timestamp_s: npt.NDArray[np.float64], counter: IntArray,
             crc_ok: npt.NDArray[np.bool_], cycle_s: float,
             strict: IntArray) -> tuple[IntArray, IntArray]:
    """The wide and narrow readings' periods of each frame (``strict``: ``frame_periods``'),
    differing from it only between two frames with a right CRC."""
    wide, narrow = strict.copy(), strict.copy()
    if len(timestamp_s) > 1:
        both = np.flatnonzero(crc_ok[1:] & crc_ok[:-1]) + 1
        dt = timestamp_s[both] - timestamp_s[both - 1]
        step = (counter[both] - counter[both - 1]) & (COUNTER_MODULO - 1)
        wide[both] = receive_periods(dt, step, cycle_s, CAPTURE_HOLD_CYCLES)
        narrow[both] = narrow_periods(dt, step, cycle_s)
    return wide, narrow


def evidence_frames(frames: FrameArrays, of_message: list[npt.NDArray[np.intp]],
                    messages: list[tuple[str, int]],
                    crc_ok: npt.NDArray[np.bool_]) -> list[npt.NDArray[np.intp]]:
    """The bus positions of each ``EVIDENCE_MESSAGES`` message's frames of its DLC with a right
    CRC (``of_message``: each message's positions; ``messages``: their names and DLCs)."""
    found = []
    for (name, length), at in zip(messages, of_message, strict=True):
        if name in EVIDENCE_MESSAGES:
            at = at[frames.dlc[at] == length]
            found.append(at[crc_ok[at]])
    return found


def pose_evidence(frames: FrameArrays, enc_pos: npt.NDArray[np.intp],
                  enc_counter: IntArray, enc_crc_ok: npt.NDArray[np.bool_],
                  poses: list[npt.NDArray[np.intp]]) -> Evidence:
    """What the pose frames ``poses`` (per message, bus positions of those with a right CRC)
    prove of the encoder frames at ``enc_pos`` (module docstring)."""
    good = np.flatnonzero(enc_crc_ok)
    taken: set[int] = set()
    skipped: set[int] = set()
    for at in poses:
        if len(at) < 2:
            continue
        counter = (frames.data[at, 1] & 0x0F).astype(np.int64)
        named = (frames.data[at, 1] >> 4).astype(np.int64)
        before = np.searchsorted(enc_pos[good], at)  # good encoder frames before each pose
        for k in range(1, len(at)):
            if (counter[k] - counter[k - 1]) & 0x0F != 1 or named[k] == named[k - 1]:
                continue  # not the next send, or the firmware did not move on: no proof
            if before[k] - before[k - 1] >= COUNTER_MODULO:
                continue
            found = _named_frame(enc_counter, good, int(before[k]), int(named[k]))
            if found is None:
                continue
            taken.add(int(good[found]))
            last_seen = int(before[k - 1])  # good frames before the previous send
            skipped.update(good[found + 1 : last_seen].tolist())
    return Evidence(frozenset(taken), frozenset(skipped - taken))


def _named_frame(enc_counter: IntArray, good: npt.NDArray[np.intp], before: int,
                 named: int) -> int | None:
    """The place in ``good`` of the latest good encoder frame among the ``before`` first with
    COUNTER ``named`` (at most 15 back), or None."""
    for back in range(before - 1, max(before - COUNTER_MODULO, -1), -1):
        if int(enc_counter[good[back]]) == named:
            return back
    return None


def settle(crc_ok: npt.NDArray[np.bool_], counter: IntArray,
           periods: tuple[IntArray, IntArray, IntArray], evidence: Evidence,
           max_delta_init: int) -> tuple[npt.NDArray[np.int8], list[int]]:
    """One message's statuses (bus order) judged with the three readings' ``periods`` (strict,
    wide, narrow) and, where they differ, with ``evidence``; and the frames neither decided
    (taken). The Profile 2 check of ``host.protocol.e2e.SequenceState`` with three windows."""
    n = len(counter)
    status = np.full(n, S_CRC, dtype=np.int8)
    windows = [0, 0, 0]
    waiting, last = True, 0
    undecided: list[int] = []
    columns = [p.tolist() for p in periods]
    ok, counters = crc_ok.tolist(), (counter & 0x0F).tolist()
    for j in range(n):
        windows = [min(w + c[j], _MAX_WINDOW) for w, c in zip(windows, columns, strict=True)]
        if not ok[j]:
            continue
        delta = (counters[j] - last) & 0x0F
        if waiting or delta == 1:
            code = S_OK
        elif delta == 0:
            status[j] = S_REPEATED
            continue
        else:
            code = _by_window_or_evidence(j, delta, windows, evidence, undecided)
        status[j] = code
        if code != S_WRONG:
            waiting, last, windows = False, counters[j], [max_delta_init] * 3
    return status, undecided


def _by_window_or_evidence(j: int, delta: int, windows: list[int], evidence: Evidence,
                           undecided: list[int]) -> int:
    """OKSOMELOST or WRONG_SEQUENCE for a frame ``delta`` after the last taken one."""
    verdicts = {delta <= w for w in windows}
    if len(verdicts) == 1:
        return S_LOST if verdicts.pop() else S_WRONG
    if j in evidence.taken:
        return S_LOST
    if j in evidence.skipped:
        return S_WRONG
    undecided.append(j)
    return S_LOST
