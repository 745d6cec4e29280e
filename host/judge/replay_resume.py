"""The log's first pose after each stall a replay lives, held to the poses its firmware can
resume at (``stallresume.resume_excess``, the whole-log judge's rule; issue #11 rule 5).

Across a stall the replay compares the log's positions with its own only by their jumps, each
held to what the encoder counts either side allow (``replay_jumps``): the recording firmware may
have taken other frames than the replayed one there (which frames its FIFO kept, a frame the
recorder missed). Over a long silence that allowance is the gap bound of the whole span: kobuki
circle 526, 11 s, ``stall=2.0:0.5,busoff=2.3:0.3,drop=0.05`` (a stall then a bus-off, one
silence 1.99 .. 2.62 s), 0.707 m, so the log with ODOM_POSE_X raised 10 mm from 2.55 s replayed
PASS, where ``odocan analyze`` FAILed it (9.563 mm beyond any pose the firmware resumes at). A
stalled firmware groups the frames one way only (fine steps to a frame its FIFO kept, one merged
step, fine steps on), whatever frames it kept: so the log's own first pose after the stall must
lie within that rule's reach of its pose before, or no firmware sent it. Not a matter of which
frames the FIFO kept, so it FAILs the life, never leaves it UNJUDGED.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from odocan.firmware.encoders import WIRE_COUNTER_BITS
from odocan.host.io.logs import FrameArrays
from odocan.host.judge.analysis import HEADING_LSB_RAD, POSITION_LSB_M
from odocan.host.judge.replay_compare import halves_by_tick, paired
from odocan.host.judge.replay_jumps import JumpModel
from odocan.host.judge.replay_track import EncoderTrack
from odocan.host.judge.stallresume import resume_excess
from odocan.host.protocol.decode import BulkDecoder
from odocan.sim import contract


def stalls_resume_excess_m(log: FrameArrays, accepted: npt.NDArray[np.bool_],
                           stall_positions: list[tuple[int, int]], reported: list[bool],
                           jumps: JumpModel, tolerance_m: float) -> float | None:
    """The most (m) the log's first pose at or after each stall's end lies beyond every pose
    its firmware can resume at from its last pose before the stall (module docstring); None
    when no stall is judged so (no pose either side, a span the rule does not take).
    ``stall_positions``: per stall, the log positions (in ``log``) of its first halted frame
    and of the frame it resumed at; ``reported``: per stall, whether the firmware's first
    summary after it newly reports TIME_LOST. Only those are judged, and only when no other
    stall lies between the two poses: a silence the firmware did not report is no halt of
    its (a hole of the recorder: it took the frames there one by one, which the rule does not
    model; kobuki random 2 with 150 lines cut, 1.0807 mm "beyond"), and two stalls are two
    merged steps (pmir 7, ``stall=7:0.5,stall=7.52:0.5``)."""
    decoder = BulkDecoder(contract.database())
    track = EncoderTrack.of(log, accepted, decoder)
    poses = paired(*halves_by_tick(log, accepted))
    if not poses or len(track.index) == 0:
        return None
    ticks = np.array(sorted(poses), dtype=np.int64)
    d = decoder.decode(log, "WHEEL_ENCODERS")
    at = np.searchsorted(d["index"], track.index)
    left, right = (d[name][at].astype(np.int64) for name in ("LEFT_COUNT", "RIGHT_COUNT"))
    robot = (jumps.geometry, jumps.integrator, min(jumps.bits, WIRE_COUNTER_BITS))
    worst: float | None = None
    bounds = [tuple(int(track.tick[min(int(np.searchsorted(track.index, p)),
                                       len(track.tick) - 1)]) for p in stall)
              for stall in stall_positions]
    for (halt_tick, end_tick), judged in zip(bounds, reported, strict=True):
        k = int(np.searchsorted(ticks, halt_tick)) - 1
        m = int(np.searchsorted(ticks, end_tick))
        if not judged or k < 0 or m >= len(ticks):
            continue
        if any(ticks[k] < b and a < ticks[m] for a, b in bounds if (a, b) != (halt_tick, end_tick)):
            continue
        a, b = (int(np.searchsorted(track.tick, int(ticks[i]))) for i in (k, m))
        x0, y0, h0 = poses[int(ticks[k])][0]
        x1, y1, _ = poses[int(ticks[m])][0]
        excess = resume_excess(
            (x0 * POSITION_LSB_M, y0 * POSITION_LSB_M, h0 * HEADING_LSB_RAD),
            (x1 * POSITION_LSB_M, y1 * POSITION_LSB_M),
            (left[a:b + 1], right[a:b + 1]), robot, tolerance_m)
        if excess is not None:
            worst = excess if worst is None else max(worst, excess)
    return worst
