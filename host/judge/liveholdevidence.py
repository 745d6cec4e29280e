"""The live judge's evidence of a hold (``stalls.hold_evidence``, one judge): the hold rule of
``livestall`` places a stall between two samples only when the firmware shows it held its pose:
the last sample's frame named twice by pose halves of one kind (one of them heard after the
frame following it came), or its poses quiet over all but ``SILENCE_CYCLES`` cycles of the time
between the two samples, ODOM_POSE_Y frames refused with their CRC right counted as sent
(``pose_sent_times``).

Issue #11 (a PASS must never hide a wrong pose): kobuki random 448, ``delay=0.3:55,busoff=5:0.2``.
The host's E2E check refused every pose from 4.82 to 5.32 s (the delay reordered them), so no
sample lay between 4.816 and 5.321 s, which name frames 21 apart: read as a hold without
evidence, the stall's span held the bus-off's gap and its allowance was 482.5 mm, which
absorbed a pose raised 10 mm from the first pose after the bus-off (0.057 mm beyond) where
``analyze``, asking evidence, finds none and FAILs it (6.12 mm).

The pose halves' names are told by ENC_COUNTER alone here (a half naming a frame 16 later
counts too): more evidence than ``analyze``'s, never less, so the live judge places a stall
wherever ``analyze`` does.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from odocan.host.judge.livewindow import CYCLE_S, Columns
from odocan.host.judge.samples import SILENCE_CYCLES


def hold_shown(window: Columns, halves: tuple[Columns | None, Columns], refused_s: Iterable[float],
               last_seq: int, span_s: tuple[float, float]) -> bool:
    """Whether the firmware shows a hold between the sample of encoder frame ``last_seq``
    (the window's seq) and the next, their ODOM_POSE_Y at ``span_s`` (bus times s):
    ``halves``: the accepted ODOM_POSE_X and ODOM_POSE_Y halves, ``refused_s``: the bus times
    of the ODOM_POSE_Y frames refused with their CRC right (module docstring). True where the
    window no longer holds the frame (nothing told: the rule as before)."""
    seqs = window.col("seq")
    i = int(np.searchsorted(seqs, last_seq))
    if i >= len(seqs) or int(seqs[i]) != last_seq:
        return True
    next_s = float(window.col("t_s")[i + 1]) if i + 1 < len(seqs) else span_s[1]
    frame_s = float(window.col("t_s")[i])
    return (_named_again(halves, int(window.col("counter")[i]), (frame_s, span_s[1]), next_s)
            or _quiet(halves[1], refused_s, span_s))


def _named_again(halves: tuple[Columns | None, Columns], counter: int,
                 span_s: tuple[float, float], next_s: float) -> bool:
    """``stalls.named_again`` of one frame: pose halves of one kind heard from the frame's own
    bus time (``span_s[0]``: no firmware names it before) up to the second sample
    (``span_s[1]``) name ENC_COUNTER ``counter`` twice or more, one of them not before the frame
    after it came (``next_s``). The sample's own half counts once: a half its ``delay`` let out
    after the next frame came is its first naming, no second (issue #11, pmir random 5,
    ``delay=0.2:40,drop=0.02``: the sample's ODOM_POSE_X 40 ms late, read as its frame named
    again, made four holds ``analyze`` does not see; their 32 mm allowance absorbed a pose
    raised 10 mm, 0.077 mm beyond where ``analyze`` FAILs it by 9.84 mm)."""
    for kind in halves:
        if kind is None or not len(kind):
            continue
        t_s = kind.col("t_s")
        named = (t_s >= span_s[0]) & (t_s <= span_s[1]) & (kind.col("enc_counter") == counter)
        late = int(np.count_nonzero(named & (t_s >= next_s)))
        if late >= 1 and int(np.count_nonzero(named)) >= 2:
            return True
    return False


def _quiet(ys: Columns, refused_s: Iterable[float], span_s: tuple[float, float]) -> bool:
    """``stalls.quiet_in`` over the pose frames sent within ``span_s``: its silences (two
    consecutive ODOM_POSE_Y, accepted or refused with their CRC right, ``SILENCE_CYCLES`` -
    0.5 cycles apart or more) leave less than ``SILENCE_CYCLES`` cycles of it talked."""
    t0_s, t1_s = span_s
    accepted = ys.col("t_s") if len(ys) else np.zeros(0)
    sent = np.sort(np.concatenate((
        [t0_s, t1_s], accepted[(accepted >= t0_s) & (accepted <= t1_s)],
        [t for t in refused_s if t0_s <= t <= t1_s])))
    gaps = np.diff(sent)
    silent_s = float(np.sum(gaps[gaps >= (SILENCE_CYCLES - 0.5) * CYCLE_S]))
    return silent_s > 0.0 and silent_s >= (t1_s - t0_s) - SILENCE_CYCLES * CYCLE_S
