"""Pose frames held back on the bus that their own message cannot tell late, told by the other
pose message (issue #11, rule "a FAIL must never blame a correct firmware").

The firmware sends ODOM_POSE_X and ODOM_POSE_Y in the same tick, each with its own E2E COUNTER,
both stepping once a send: the two COUNTERs keep one offset (0 from power-up). A run of one
message's frames held back on the bus (``delay=P:N``) while none of its on-time frames is heard
reads in order within that message (``e2e_evidence.send_readings``: the first after a
"silence"), but the other message's on-time frames heard meanwhile are sends ahead of it.

Kobuki, random, seed 11, 12 s, ``delay=0.5:150``: ODOM_POSE_Y COUNTER 7 to 12 (ENC_COUNTER 12,
3, 4, 5, 8, 10), sent 10.081-10.181 s, were heard 150 ms late at 10.231-10.331 s with no on-time
Y frame among them; ODOM_POSE_X COUNTER 14 of 10.221 s and 0 of 10.261 s were on time. Read in
order, Y 9 (naming 4) and 10 (naming 5) "proved" the on-time WHEEL_ENCODERS COUNTER 5 of
10.290 s taken (it named the 5 of 10.130 s): the host's E2E took it where the firmware took the
late 6 heard with it, the reference re-primed on the wrong frame and FAILed the correct firmware
by 11.09 mm and 31.56 mrad.

``crossed_late`` marks such frames; ``pose_evidence`` leaves out those its own message reads in
order (they prove nothing). A frame its own message already reads late keeps its sent place
(kobuki seed 9 of the same line needs those: leaving every marked frame out FAILed it by 26 mm)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK, POSE_PERIOD_S
from odocan.host.protocol.e2e_sends import sends_between

IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]
TWIN_S = 1e-3  # the X and Y frames of one send: heard this close together (one tick's sends)
LATE_PERIODS = 0.5  # a frame of a send already heard in the other message, this much later: late


def counter_offset(t_a: npt.NDArray[np.float64], c_a: IntArray,
                   t_b: npt.NDArray[np.float64], c_b: IntArray) -> int | None:
    """The COUNTER offset (b - a mod 16) of two messages sent in the same tick: the most common
    over pairs heard within ``TWIN_S``; None when no pair is (nothing is told then)."""
    if len(t_a) == 0 or len(t_b) == 0:
        return None
    after = np.minimum(np.searchsorted(t_a, t_b), len(t_a) - 1)
    before = np.maximum(after - 1, 0)
    best = np.where(np.abs(t_a[before] - t_b) < np.abs(t_a[after] - t_b), before, after)
    twin = np.abs(t_a[best] - t_b) < TWIN_S
    if not twin.any():
        return None
    offsets = (c_b[twin] - c_a[best[twin]]) & ENC_COUNTER_MASK
    return int(np.bincount(offsets, minlength=ENC_COUNTER_MASK + 1).argmax())


def crossed_late(timestamp_s: list[npt.NDArray[np.float64]], counter: list[IntArray]
                 ) -> list[BoolArray]:
    """Per message (two: the pose messages, each in bus order): its frames sent before a frame
    of either message already heard, read on one COUNTER scale (the second message's COUNTER
    less ``counter_offset``): a COUNTER behind the latest-sent one (1..7 sends), or its very
    send heard ``LATE_PERIODS`` or more after the other message's frame of it. Frames of one
    message alone (no pair heard together) are never marked."""
    marks = [np.zeros(len(t), dtype=bool) for t in timestamp_s]
    if len(timestamp_s) != 2:
        return marks
    offset = counter_offset(timestamp_s[0], counter[0], timestamp_s[1], counter[1])
    if offset is None:
        return marks
    scaled = [counter[0], (counter[1] - offset) & ENC_COUNTER_MASK]
    t_all = np.concatenate(timestamp_s)
    which = np.concatenate([np.zeros(len(timestamp_s[0]), dtype=np.int64),
                            np.ones(len(timestamp_s[1]), dtype=np.int64)])
    place = np.concatenate([np.arange(len(t)) for t in timestamp_s])
    order = np.argsort(t_all, kind="stable")
    top_c, top_s = -1, 0.0
    for i in order.tolist():
        m, k = int(which[i]), int(place[i])
        c, t = int(scaled[m][k]), float(t_all[i])
        if top_c >= 0:
            sends = sends_between(t - top_s, c - top_c, POSE_PERIOD_S)
            if sends < 0 or (sends == 0 and t - top_s >= LATE_PERIODS * POSE_PERIOD_S):
                marks[m][k] = True
                continue
            if sends == 0:
                continue
        top_c, top_s = c, t
    return marks


def crossed_late_of(frames: FrameArrays, poses: list[npt.NDArray[np.intp]]) -> list[BoolArray]:
    """``crossed_late`` of the pose frames at bus positions ``poses`` (per message)."""
    return crossed_late([frames.timestamp_s[at] for at in poses],
                        [(frames.data[at, 1] & ENC_COUNTER_MASK).astype(np.int64)
                         for at in poses])
