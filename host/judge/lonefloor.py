"""The earliest encoder frame a lone pose half may name: the frame a pose sent before it named
(issue #11: a PASS must never hide a wrong pose; ``host.judge.candidates``).

A lone half the reference at its matched frame cannot judge is judged against every frame of
its ENC_COUNTER it may name, from a counter lap before the matched one (a stall's backlog, a
half held back on the bus). On a lossy bus such an earlier frame is often one the log lacks,
bounded only by its neighbours less the plausibility bound's reach of a period (pmir: 40 mm):
a fit for almost any value. pmir random seed 8, ``drop=0.2,stall=5:3``: the ODOM_POSE_Y at
9.781 s (its X lost) raised 10 mm fitted seq 961, a lap before the 977 it names, at -10.4 mm
and PASSed; yet the pose sent just before it (its Y heard at 9.761 s, COUNTER one less) named
seq 975.

The firmware takes encoder frames in the sender's sequence (its E2E check refuses an older
one), so a pose names no frame before one a pose sent before it named. A frame q of the half's
own message heard before the half r was sent before it (or is r's own copy), unless r was held
back on the bus past q: q sent k >= 1 sends after r, k = (COUNTER(q) - COUNTER(r)) mod 16 or a
lap more (one send a pose period at most), and heard before r, holds r back at least
(t_r - t_q) + k * POSE_PERIOD_S. Where that is ``HOLD_PERIODS`` pose periods (300 ms) or more
(a frame sent in order with the ones around it: 16 periods; the rig's faults hold a frame back
240 ms at most, and ``latenames`` reads one held back half a lap as unreadable), q was sent
before r. Not told apart: a firmware reboot between r and q, which restarts the COUNTER, with r
held back past the reboot's silence (no test's faults hold a frame back that long). Where
such a q is a kept sample's half (both halves of a pose, judged; one ``resendalias`` says may
name another frame names a later one, if not that: it bounds all the same), the latest frame
such a q names is the half's floor: its candidates start there (pmir seed 1,
``delay=0.5:150,drop=0.1``: raised 10 mm, 67 lone halves PASSed without a floor, 51 with the
aliasing halves left out of the q, 17 with them in).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from odocan.host.judge.candidates import Half
from odocan.host.judge.samples import IntArray, PoseHalves
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP, POSE_PERIOD_S

HOLD_PERIODS = 15  # a pose frame held back this many pose periods: beyond any the bus makes
LAP = ENC_COUNTER_LAP  # 16: the pose frames' COUNTER lap


def with_floors(lone: list[Half], halves: PoseHalves, ix: IntArray, iy: IntArray,
                kept_enc: IntArray) -> list[Half]:
    """``lone`` (``candidates.lone_halves_of`` of the X halves at ``ix`` and the Y halves at
    ``iy``, X ones first) each with its floor (module docstring; ``kept_enc``: the kept
    samples' encoder frames)."""
    floors = [*_floors(halves.px, halves.ex, ix, kept_enc),
              *_floors(halves.py, halves.ey, iy, kept_enc)]
    return [dataclasses.replace(h, floor=f) if f >= 0 else h for h, f in zip(lone, floors,
                                                                             strict=True)]


def _floors(frames: dict[str, np.ndarray], named: IntArray, rows: IntArray,
            kept_enc: IntArray) -> list[int]:
    """Per half of one message at positions ``rows`` of ``frames`` (naming ``named``): the
    latest frame a kept sample's half of that message sent before it names; -1: none."""
    counter = np.asarray(frames["COUNTER"], dtype=np.int64)
    index = np.asarray(frames["index"], dtype=np.int64)
    periods = np.asarray(frames["timestamp_s"], dtype=np.float64) / POSE_PERIOD_S
    usable = (named >= 0) & np.isin(named, kept_enc)
    out = []
    for r in rows.tolist():
        sends = (counter - counter[r] - 1) % LAP + 1  # q sent that many after r, at the least
        held = periods[r] - periods + sends  # r held back past q (pose periods), at the least
        before = usable & (index < index[r]) & (held >= HOLD_PERIODS)
        out.append(int(named[before].max()) if before.any() else -1)
    return out
