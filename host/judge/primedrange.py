"""The frames a power-up whose FIFO was drained may have primed on, by its count page and its
first pose (issue #11: "a PASS must never hide a wrong pose", "a FAIL must never blame a
correct firmware").

The first count page says the firmware had not accepted the log's first ``k`` encoder frames
(``powerup.primed_after``). A recorder stamping ODOM_STATUS late (a gateway's 10-50 ms) puts
that page, and the summaries that bound its tick, after more encoder frames than the firmware
had counted, so ``k`` is only ever too large; the firmware's first pose (not delayed) names a
frame ``n`` it had integrated, at or after its priming frame. So it primed on one of frames
0 .. min(``k``, ``n``), and no time on the log tells a late stamp from an honest one: 10 ms
late, the page says 2 and the pose names 2 while the firmware primed on 1. Taking ``k`` alone
FAILed a correct firmware whose robot moved at power-up; vetoing it for a fitted start PASSed
one 1 m off. The life is judged from (0, 0, 0) on each of those frames instead
(``primedon.judged_from_each``: PASS from one, the frame said; FAIL from all, the candidates
said), the count's own frame first."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.powerup import first_pose_named, primed_after
from odocan.host.judge.primedon import FRAMES_KEY, WHY_KEY, start_pose_primed_on
from odocan.host.judge.samples import Encoders
from odocan.host.protocol.decode import BulkDecoder
from odocan.sim.robot import RobotProfile

PAGE_KIND = "power_up_primed_late"  # the count page says it primed on the log's k-th frame
PAGE_WHY = ("the firmware's first count page (ENC_E2E_OK, at UPTIME 0 in its first cycle) "
            "says it primed after the log's first encoder frames, on frame {k} at most (a "
            "recorder stamping ODOM_STATUS late overcounts), and its first pose names frame {n}: "
            "it primed on one of frames {frames}")


def primed_frames(k: int, named: int | None) -> list[int]:
    """The frames it may have primed on (module docstring), the latest first (the count's
    ``k`` when its first pose, naming ``named``, allows it): 0 .. min(``k``, ``named``)."""
    top = k if named is None else max(0, min(k, named))
    return list(range(top, -1, -1))


def primed_range_event(frames: FrameArrays, accepted: npt.NDArray[np.bool_],
                       decoder: BulkDecoder, enc: Encoders, t_s: float,
                       judged: tuple[RobotProfile, str]) -> list[dict[str, Any]]:
    """The report's event whose candidates (``FRAMES_KEY``: each frame and its start pose at
    frame 0) ``primedon.each_prime`` judges the life from; none when the count page proves
    no late priming (``powerup.primed_after``). ``t_s``: the first sample's bus time."""
    k = primed_after(frames, accepted, decoder)
    if k is None:
        return []
    named = first_pose_named(frames, accepted, decoder)
    tries = [p for p in primed_frames(k, named) if p < len(enc.index)]
    return [] if not tries else [{"kind": PAGE_KIND, "t_s": t_s,
             WHY_KEY: PAGE_WHY.format(k=k, n="?" if named is None else named, frames="{frames}"),
             FRAMES_KEY: [[p, list(start_pose_primed_on(enc, p, *judged))] for p in tries]}]
