"""Whether a replayed stall reproduced the recording board's, told by the poses after it
(``replay_lives``: a life that departs after a stall is UNJUDGED unless this says so).

What a halted board's receive FIFO kept (``replay_halts``) changes which encoder frames its
firmware stepped over when it resumed: a FIFO the replay did not reproduce moves the replayed
pose off the log's from the first pose after the stall on (integrated from other frames), and
never back, as a pose is the sum of its steps. Once both firmwares have taken the same frame
after the FIFO drained (``HW_RX_FIFO_FRAMES`` ticks after the halt's end) and sent the same pose
naming it, byte for byte, their state is one: the pose, the frame's counts, and the E2E check's
last COUNTER (``firmware.e2e``: reset on every accepted frame). A departure after
``REPRODUCED_POSES`` such poses is no FIFO's, it is the log's own, and is judged.

Found on kobuki random 700, 8 s, ``busoff=1.5:0.2,delay=0.1:150,stall=3.1:0.3`` and kobuki
figure8 674, 9 s, ``reboot=1.8:0.2,stall=5.6:0.2,delay=0.3:55``: with ODOM_POSE_X raised 10 mm
from 3.8 s (6.2 s), 16 (9) poses from the stall at 3.09 s (5.60 s) on replayed identical, the
rest 10 mm off, and the life was UNJUDGED ("which frames the recording board's receive FIFO
kept is more than the log tells") where it is a FAIL. The firmware's own E2E pages
(ENC_E2E_OK, ENC_E2E_LOST) cannot tell it: under ``delay`` the replayed firmware counts other
late frames than the recording one did (kobuki 674, correct: 139 OK and 235 lost after the
stall against the log's 137 and 234) while its every pose is the log's.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.analysis import POSITION_LSB_M
from odocan.host.judge.replay_compare import onboard_by_tick, recorder_holes
from odocan.host.judge.replay_track import EncoderTrack
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import check_frames
from odocan.sim import contract
from odocan.sim.mcu import HW_RX_FIFO_FRAMES

REPRODUCED_POSES = 3  # identical poses after the FIFO drained that show the stall reproduced

Poses = dict[int, list[tuple[int, int, int]]]


def kept_stall(log: FrameArrays, log_accepted: np.ndarray[Any, np.dtype[np.bool_]],
               replayed: FrameArrays, halts: list[tuple[int, int]]) -> dict[str, Any] | None:
    """The stall the life's first differing pose follows, when the replay reproduced it (module
    docstring): its ``halts`` index, the identical poses from it to that pose, and the largest
    position difference (m, as they are) from that pose to the next stall or hole of the log;
    None when that pose comes before any stall, or fewer than ``REPRODUCED_POSES`` identical
    poses precede it after the FIFO drained, or after a hole of the log between (the recording
    firmware took frames there the replay is not fed: kobuki figure8 673, a hole of 35 ms as the
    stall at 5.59 s ended). ``log``, ``replayed``: one life's frames, both from its first
    encoder frame; ``halts``: its stalls, [first, end) ticks counted from that frame."""
    old = onboard_by_tick(log, log_accepted)
    new = onboard_by_tick(replayed, check_frames(replayed)[1])
    common = sorted(old.keys() & new.keys())
    off = [t for t in common if len(set(old[t]) | set(new[t])) > 1]
    if not off:
        return None
    before = [k for k, (first, _) in enumerate(halts) if first <= off[0]]
    if not before:
        return None
    k = before[-1]
    first, end = halts[k]
    holes = _hole_ticks(log, log_accepted)
    # the latest stall or hole before the first differing pose, each shown reproduced
    since = [end + HW_RX_FIFO_FRAMES] + [t for t in holes if first < t <= off[0]]
    if any(len([t for t in common if s <= t < off[0]]) < REPRODUCED_POSES for s in since):
        return None
    limit = min([h[0] for h in halts[k + 1:]] + [t for t in holes if t > off[0]]
                + [common[-1] + 1])
    after = [t for t in common if off[0] <= t < limit]
    return {"stall": k, "identical_after": len([t for t in common if first <= t < off[0]]),
            "compared_after": len(after), "max_position_diff_m": _position_diff_m(old, new, after)}


def _hole_ticks(log: FrameArrays, accepted: np.ndarray[Any, np.dtype[np.bool_]]) -> list[int]:
    """The ticks (of the encoder frame after each) of the log's holes: the recording firmware
    took frames there the replay is not fed (``replay_compare.recorder_holes``), so positions
    after one may differ as they are."""
    track = EncoderTrack.of(log, accepted, BulkDecoder(contract.database()))
    found = [int(h["before"]) for h in recorder_holes(log)]
    at = np.searchsorted(track.index, found, "right")
    return [int(track.tick[a]) for a in at.tolist() if a < len(track.tick)]


def _position_diff_m(old: Poses, new: Poses, ticks: list[int]) -> float:
    """The largest position difference, as they are, between any pose the log and the replay
    sent naming one of ``ticks``."""
    diff = [float(np.hypot(a[0] - b[0], a[1] - b[1]))
            for t in ticks for a in old[t] for b in new[t]]
    return max(diff, default=0.0) * POSITION_LSB_M
