"""The live judge's first pose made a COUNTER lap or more after the frame it names
(``host.judge.lapfirst``, the whole log's rule): a firmware still starting when the robot's
frames began names, by the 4-bit ENC_COUNTER, a frame 16 or more before the newest of that
COUNTER, which the plain rule pairs it with.

Live, the first ODOM_POSE_X is heard before its Y half and its twist: as ``floodnames`` resolves
a flood's names, its HEADING alone picks the frame, from the start of the frames heard (the
life's pose 0 at its first frame: the anchor no pose gives yet), among the newest frame of its
COUNTER and each a lap before it back to the first frame heard, only when exactly one lies
within ``floodnames.MATCH_LSB`` and that one is not the newest. Every frame of that tick (its Y
half, the twist) follows (``LiveFloodNames.follow``), and each value is judged against the
reference at the frame picked: a pose whose heading fits an older lap by chance (5 values of
65536 per candidate) but whose X, Y or DISTANCE do not FAILs there, as at the newest.

Not to a frame beyond the live window (``ENC_WINDOW`` frames before the latest: its reference
no longer kept, ``LiveFloodNames.pose_x``): a first pose that far behind came after a stall (5 s
of frames the firmware did not answer), which the live stall rules judge (``livereprime``);
moved there it went unjudged and a correct firmware's PASS became UNJUDGED
(``tests/test_stall_beyond_window.py`` power-up 6 s, 10 s; ``test_reprime_count_live.py``)."""

from __future__ import annotations

from odocan.host.judge.floodnames import pick
from odocan.host.judge.reference import Geometry
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP

# one frame kept by ``LiveFloodNames``: the tracker's seq, bus time s, cumulative counts
Kept = tuple[int, float, int, int]


def first_lap(kept: dict[int, Kept], sseq: int, heading_raw: int, geometry: Geometry
              ) -> tuple[int, int] | None:
    """The first pose's frame (``sseq``: the sender sequence its name resolves to by the plain
    rule; ``heading_raw``: its HEADING, BAM16) a lap or more before it when its heading picks
    that one (module docstring): (the sequence number picked, the tracker's seq of it); None
    when the frames heard do not reach back to the first (0) or the pick is not one older."""
    if 0 not in kept:
        return None  # the first frame heard forgotten: no start to carry from
    cands = [s for s in range(sseq, -1, -ENC_COUNTER_LAP) if s in kept]
    if len(cands) < 2 or cands[0] != sseq:
        return None
    start = kept[0]
    found = pick(geometry, (start[2], start[3], 0),
                 [(kept[c][2], kept[c][3]) for c in cands], heading_raw)
    if not found:  # None, or 0: the newest (the plain rule's own)
        return None
    return cands[found], kept[cands[found]][0]
