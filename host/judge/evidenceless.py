"""An ambiguous gap the log gives no evidence for (issue #11, rule 3: a FAIL must never blame a
correct firmware; ``host.judge.ambiguity``).

A gap of the log's encoder frames whose periods reach the ambiguous step is mirrored as a
re-prime (COUNTER_RESET, nothing integrated across it). That holds for the sender's silence; a
recorder that lost the frames alone holds a firmware that took them one by one. Where the log
says which, it decides already: pages proving frames taken (``holetaken``: ``Seen.through``),
the firmware's own COUNTER_RESET word near the threshold (``nearthreshold``), pages proving the
gap missed or the log's frames taken (``Seen.gap_missed``, ``Seen.took_across``). Where it holds
none of these, the judge cannot know: it takes either, choosing by the firmware's next pose.
From the last on-board sample before the gap to the first after it, both candidates (the
re-prime: no step into the frame after the gap; the gap taken: the log's step across it, judged
then with the gap's usual merge allowance, ``gapbound``) are integrated from the on-board pose
before; the one ending nearer the on-board pose after (position and heading in LSBs) is taken
(into ``Seen.through``, as a hole proven taken). Either is then judged as usual: a pose that
fits neither still FAILs. Each choice is local (anchored on the on-board pose before its gap).
The live judge (the monitor, the bridge) holds both candidates and the samples after such a hole
until its pages had their time, then chooses the same way (``host.judge.livechoice``); the
streamed judge refuses such a life (``host.judge.unseenrestart``: the whole log's judge judges).
"""

from __future__ import annotations

from odocan.host.judge.gapseen import Seen


def evidenceless(seen: Seen, frame: int) -> bool:
    """Whether nothing in the log tells whether the firmware re-primed on the encoder frame
    ``frame`` after a gap of the log (module docstring)."""
    if frame in seen.through or seen.gap_missed(frame) or seen.took_across(frame):
        return False
    gap = seen.resets.long_gaps.get(frame)
    return gap is None or seen.resets.told(gap[1]) is None
