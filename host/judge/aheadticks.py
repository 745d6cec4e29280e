"""A power-up tick told looking ahead (``bootticks.boot_ahead``), its evidence read without the
frames the bus held back (issue #11), for every judge: the whole log (``ahead_ticks``), the
streamed ``analyze`` (``stream_lives``) and the live ones (``SourceWatch.hear_pose``).

``boot_ahead`` takes a summary of UPTIME 0 and COUNTER 0 for a new firmware's power-up tick when
its first pose after it (COUNTER 0, or a small COUNTER with its power-up pose lost) or the
summary breaks its message's sequence. Within one life that summary comes every 0.8 s of UPTIME
0 (ODOM_STATUS laps 16 frames at two a 100 ms cycle), and a bus that holds frames back makes
the breaks: a pose sent before frames already heard fills a hole of its sender's sequence
(``liveheldpose``), a status frame likewise (``livelatestatus``); their COUNTER's step says
nothing of a new life. Kobuki random 906, ``reboot=1.5:0.3,delay=0.1:200``: the summary of
COUNTER 0 at 2.601 s, 0.8 s after the power-up, in order, and the pose of COUNTER 0 sent at
2.441 s heard at 2.641 s after COUNTER 7: told a second reboot by every judge, the correct
firmware FAILed 32.9 mm. Kobuki random 695, ``reboot=0.5:0.3,delay=0.1:150``: the summary of
COUNTER 0 at 1.601 s right after a page held back from 1.401 s, its first pose COUNTER 1 held
back from 1.461 s, its twist too (a DISTANCE fall; ``distfall`` leaves held twists out):
told a reboot at 1.601 s.
So a held-back pose's break is no evidence
(``pose_held``: the same ``PoseOrder`` as ``SourceWatch.observe``'s power-up tick rule); the
summary's own break and the twists' DISTANCE falling (``fell``) still are, and a new firmware
whose first tick the bus held back keeps its pose's (the frames heard in order after the hole
broke first). The summary's break stays evidence even against a status frame held back: it is
one of two asked for, and kobuki random 693 ``reboot=0.5:0.3,delay=0.1:150`` (a real reboot
at 0.801 s after 0.3 s of boot silence, its page of 0.401 s held back to 0.551 s) has no other
sequence broken: dropping it left the reboot untold and FAILed the correct firmware.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.bootticks import (
    TWIST_COUNTERS,
    Latest,
    ahead_candidate,
    boot_ahead,
    continues_summary,
    fell_around,
    pose_rows,
)
from odocan.host.judge.distfall import Falls
from odocan.host.judge.heldsummaries import pose_zeros_held
from odocan.host.judge.latefall import continues_twice, fell_late
from odocan.host.judge.liveheldpose import PoseOrder
from odocan.host.judge.navrestart import second_evidence
from odocan.host.protocol.decode import BulkDecoder


def boot_ahead_heard(summary_s: float, status_broke: bool, t_s: float, counter: int,
                     before: tuple[float, int] | None, pose_held: bool,
                     fell: bool = False) -> bool:
    """``boot_ahead`` of the first pose after a summary (bus time ``t_s``, E2E ``counter``;
    ``before``: the pose heard before it) where ``pose_held``: the bus held that pose back
    within its sender's unbroken sequence (``PoseOrder.hear``), so its COUNTER's step breaks
    nothing; only the summary's break (``status_broke``) with a fall (``fell``), or with a
    pose of COUNTER 0 soon after it, tells then."""
    if not pose_held:
        return boot_ahead(summary_s, status_broke, t_s, counter, before, fell)
    if counter == 0:  # soon after the summary, which broke its own sequence
        return status_broke and boot_ahead(summary_s, True, t_s, counter, None)
    return boot_ahead(summary_s, status_broke, t_s, counter, None, fell)


def ahead_ticks(frames: FrameArrays, decoder: BulkDecoder, positions: npt.NDArray[np.int64],
                uptime_s: npt.NDArray[np.int64], counters: npt.NDArray[np.int64],
                t_s: npt.NDArray[np.float64], statuses: Latest) -> npt.NDArray[np.bool_]:
    """``boot_ahead_heard`` (and ``continues_summary``) of the summaries at ``positions`` (in
    order, their CRC holding: UPTIMEs, COUNTERs, bus times; ``statuses``: ``status_before`` of
    each) at once, their first pose after them in ``frames`` (before the next summary)."""
    where, t_pose, counter = pose_rows(frames, decoder)
    found = np.zeros(len(positions), dtype=bool)
    if len(where) == 0 or len(positions) == 0:
        return found
    k = np.searchsorted(where, positions)  # the first pose after each
    n = len(positions)
    candidates = np.flatnonzero((uptime_s == 0) & (counters == 0) & (k < len(where)))
    if len(candidates) == 0:
        return found
    falls = second_evidence(frames, decoder, TWIST_COUNTERS)[0]  # ``navrestart``
    held_poses = pose_zeros_held(PoseOrder(), False, frames, decoder, positions)[2]
    for i in candidates.tolist():
        j = int(k[i])
        if i + 1 < n and where[j] > positions[i + 1]:
            continue
        status = None if statuses[1][i] < 0 else (float(statuses[0][i]), int(statuses[1][i]))
        broke = ahead_candidate(0, 0, float(t_s[i]), float(t_s[i - 1]) if i else None, status)
        before = None if j == 0 else (float(t_pose[j - 1]), int(counter[j - 1]))
        fell = fell_around(falls, float(t_s[i])) or _fell_late(falls, i, t_s, uptime_s, counters)
        found[i] = (broke is not None and i + 1 < n
                    and boot_ahead_heard(float(t_s[i]), broke, float(t_pose[j]), int(counter[j]),
                                         before,
                                         bool(held_poses[j]), fell)
                    and continues_summary(float(t_s[i]), float(t_s[i + 1]), int(uptime_s[i + 1]),
                                          int(counters[i + 1])))
    return found


def _fell_late(falls: Falls, i: int, t_s: npt.NDArray[np.float64],
               uptime_s: npt.NDArray[np.int64], counters: npt.NDArray[np.int64]) -> bool:
    """``latefall``: the summary ``i``'s first twist heard fell by the second summary after it,
    which continues its sequence (read there live: ``SourceWatch.told_ahead``)."""
    if i + 2 >= len(t_s) or not continues_twice(float(t_s[i]), float(t_s[i + 2]),
                                                int(uptime_s[i + 2]), int(counters[i + 2])):
        return False
    return fell_late(falls, float(t_s[i]), float(t_s[i + 2]))
