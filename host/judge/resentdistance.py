"""Resent ODOM_TWIST frames (issue #11): every twist frame's DISTANCE is judged, not only the
first naming an encoder frame (``distance.DistanceJudge.take``, ``livedistance``).

A firmware that ticks without a new encoder frame (lost frames, a hold) sends ODOM_TWIST again
naming the same ENC_COUNTER; nothing moves its path length but an encoder frame, so a resend
carries the DISTANCE the first did. A resend is judged as a sample of the frame it names (the
same reference, slack and allowances: a correct firmware's resend gives the first's interval
again and changes nothing; one that differs narrows it, or empties it: DISTANCE WRONG). Only a
chain of resends right after a judged twist frame is judged: one after a twist left out (the
first after a stall names a frame ENC_COUNTER cannot resolve; one naming none) is left out too.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

BoolArray = npt.NDArray[np.bool_]


def resends_too(first: BoolArray, resend: BoolArray, judged_before: bool) -> BoolArray:
    """Which twist frames in bus order are judged: ``first`` (the first naming its frame,
    judged), and each ``resend`` (naming the frame the one before it named) right after a
    judged one (``judged_before``: the frame before the first given was)."""
    breaks = np.concatenate(([True], ~resend))  # index 0: the frame before these
    ok_at = np.concatenate(([judged_before], first))
    last_break = np.maximum.accumulate(np.where(breaks, np.arange(len(breaks)), 0))
    ok: BoolArray = (first | (resend & ok_at[last_break[1:]])).astype(bool)
    return ok
