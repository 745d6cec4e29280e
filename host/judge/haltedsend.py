"""An ODOM_STATUS summary its firmware made before it halted and sent after: no second source.

A source's UPTIME (whole seconds) minus bus time stays within ``sources.UPTIME_MATCH_S`` of its
offset; two offsets that interleave are two firmwares on one node ID (``sources.SourceWatch``).
An MCU halted in the middle of a tick (a debugger halt, ``kill -STOP`` of ``odocan firmware``,
a process starved by a loaded host) sends the rest of that tick's frames when it resumes: a
summary whose UPTIME is the one read before the halt, heard the halt's length late. Its offset
lies that far behind; the next summary, made after the halt, is back on the offset: two offsets
interleave, and every judge said two firmwares answered. Issue #11 (trial38): ``odocan
firmware`` stopped 2 s under a loaded host: the monitor said CONFLICT "two senders of
ODOM_STATUS interleave" for the one resumed firmware; ``kill -STOP`` landed between its
ODOM_POSE_X and the rest of its tick, whose summary (UPTIME 3, COUNTER 14) came 2.1 s late.

Such a summary continues its sender's E2E sequence (its COUNTER follows the ODOM_STATUS frame
heard before it), its UPTIME neither goes back nor says INIT after running, and it is on the
offset at the bus time of that frame: it was made then, with nothing sent since. It says the
UPTIME its firmware had then, as a frame the bus held back (``livelatestatus``): passed over. A
second firmware's summary is not: while both answer, their frames interleave with no silence
for its UPTIME to be on the first one's offset that long before; one passed over by chance
(its COUNTER 1 in 16) leaves the next to tell it. One rule for every judge: ``observe``'s.
"""

from __future__ import annotations

from odocan.host.protocol.busfacts import STATUS_COUNTER_LAP


def sent_after_halt(summary: tuple[float, int, str, int | None], offset_s: float,
                    match_s: float, last: tuple[int, str],
                    status_before: tuple[float, int] | None) -> bool:
    """Whether the summary (bus time s, UPTIME s, STATE, E2E COUNTER; None: not told), off the
    source's ``offset_s`` (UPTIME - bus time) by more than ``match_s``, was made before its
    firmware halted and sent after (module docstring); ``last``: the UPTIME and STATE of the
    summary observed before it; ``status_before``: the bus time and COUNTER of the ODOM_STATUS
    frame (any page) heard before it."""
    t_s, uptime_s, state, counter = summary
    if counter is None or status_before is None:
        return False
    before_s, before_counter = status_before
    if counter != (before_counter + 1) % STATUS_COUNTER_LAP or uptime_s < last[0]:
        return False  # not the sequence's next frame, or its UPTIME went back: a reboot's
    if state == "INIT" and last[1] not in ("", "INIT"):
        return False
    late = abs((uptime_s - t_s) - offset_s) > match_s
    return late and abs((uptime_s - before_s) - offset_s) <= match_s
