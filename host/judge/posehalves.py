"""What each half of an on-board pose carries (dbc/odocan.dbc), and the heading of a half whose
partner was lost, read nearest another source's heading at the frame it names: the one rule of
the judges (``lonehalves``: the float64 reference's heading) and of the replay
(``replay_lone``: the replayed firmware's).

ODOM_POSE_X carries X and HEADING (u16 binary angle, [0, 2 pi)), ODOM_POSE_Y carries Y and TURNS
(i16, wrapping: the whole turns of the unwrapped heading, TURNS * 2 pi + HEADING). A lone X half
lacks the whole turns: they are those that bring its HEADING nearest the other heading. A lone Y
half lacks HEADING: it is the binary angle (0 .. 65535) that brings TURNS * 2 pi + HEADING
nearest the other heading, so the half's heading error is how far the other heading lies outside
the turn TURNS names. Headings here are in BAM16 units (2 pi / 65536 rad), unwrapped.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

# (message, its position signal, its heading signal): what each half carries
HALVES = (("ODOM_POSE_X", "X", "HEADING"), ("ODOM_POSE_Y", "Y", "TURNS"))
BAM = 65536  # BAM16 units in a turn
TURNS_SPAN = 65536  # TURNS is an i16: it wraps every 65536 turns

FloatArray = npt.NDArray[np.float64]


def x_half_heading_bam(heading_raw: npt.ArrayLike, near_bam: npt.ArrayLike) -> FloatArray:
    """The unwrapped heading (BAM16) of ODOM_POSE_X halves of HEADING ``heading_raw``: the whole
    turns that bring it nearest ``near_bam`` (the other source's unwrapped heading, BAM16)."""
    heading = np.asarray(heading_raw, dtype=np.float64)
    near = np.asarray(near_bam, dtype=np.float64)
    out: FloatArray = heading + BAM * np.round((near - heading) / BAM)
    return out


def y_half_heading_bam(turns_raw: npt.ArrayLike, near_bam: npt.ArrayLike) -> FloatArray:
    """The unwrapped heading (BAM16) of ODOM_POSE_Y halves of TURNS ``turns_raw``: TURNS taken
    round its i16 wrap nearest ``near_bam``'s turns, plus the BAM16 in [0, 65535] that brings
    it nearest ``near_bam`` (the other source's unwrapped heading, BAM16)."""
    turns = np.asarray(turns_raw, dtype=np.float64)
    near = np.asarray(near_bam, dtype=np.float64)
    turns = turns + TURNS_SPAN * np.round((near / BAM - turns) / TURNS_SPAN)
    heading = np.clip(np.round(near - turns * BAM), 0, BAM - 1)
    out: FloatArray = turns * BAM + heading
    return out
