"""ODOM_TWIST DISTANCE judged chunk by chunk (``host.judge.distance``): one pass over a life,
the firmware's steps from ``stream.StreamReference`` (its ``firmware_steps``, element for
element the whole log's) and the samples from ``stream_twist.StreamTwist`` (its causal pairing,
``compare.check_twist``' samples), fed to the same ``DistanceJudge`` as the whole-log analyze:
the same result at any chunk size (tests/test_distance.py)."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any

import numpy as np

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.distance import DistanceJudge
from odocan.host.judge.reference import Geometry
from odocan.host.judge.samples import WIRE_COUNTER_BITS, FloatArray, IntArray
from odocan.host.judge.stalls import alive_times
from odocan.host.judge.stream import StreamE2E, StreamEncoders, StreamReference
from odocan.host.judge.stream_life import _take
from odocan.host.judge.stream_twist import StreamTwist
from odocan.host.protocol.decode import BulkDecoder
from odocan.sim.robot import RobotProfile

if TYPE_CHECKING:  # a cantools Database or a plan of it (host.protocol.dbcplan)
    from odocan.host.protocol.dbcplan import DatabaseSpec


KEPT_TIMES = 256  # encoder frames' bus times kept from the chunks before (a twist names one)


def stream_distance(frames: Callable[[], Iterable[FrameArrays]], db: DatabaseSpec,
                    robot: RobotProfile, integrator: str, e0: int, judge: DistanceJudge
                    ) -> dict[str, Any]:
    """The report's ``onboard_distance_vs_reference`` of one life (``frames``: its chunks)
    from encoder frame ``e0`` on (``judge``: its start, breaks and lossy spans)."""
    decoder = BulkDecoder(db)
    e2e, numbering = StreamE2E(db), StreamEncoders(decoder)
    reference = StreamReference(Geometry.of(robot), integrator,
                                min(robot.counter_bits, WIRE_COUNTER_BITS),
                                judge.max_wheel_speed_mm_s)
    count = 0
    enc_t = np.zeros(0)
    # the firmware's accepted ODOM_STATUS frames: bus times, encoder frames logged before each;
    # the latest of the chunks before and this chunk's (``DistanceJudge.talked_before``, as the
    # whole log's ``check_distance``: a twist resolves in its own chunk)
    alive: tuple[FloatArray, IntArray] = (np.zeros(0), np.zeros(0, np.int64))

    def take(e: IntArray, raw_mm: IntArray, t_s: FloatArray) -> None:  # this chunk's twists
        if len(raw_mm) and raw_mm[0] < 0:  # a DBC without DISTANCE (-1): nothing to judge
            return
        if len(t_s):
            judge.talked_before(float(t_s[0]), *alive)
        k = e - (count - len(enc_t))  # the named frame among the latest kept
        kept = (k >= 0) & (k < len(enc_t))
        named_t = (np.where(kept, enc_t[np.clip(k, 0, len(enc_t) - 1)], np.nan) if len(enc_t)
                   else np.full(len(e), np.nan))
        judge.take(e, raw_mm, t_s, count - len(enc_t) + np.searchsorted(enc_t, t_s), named_t)

    twist = StreamTwist(decoder, robot, on_distance=take)
    for chunk in frames():
        accepted = e2e.feed(chunk)
        enc = numbering.feed(chunk, accepted)
        g = count + np.arange(len(enc.index), dtype=np.int64)
        status_s = alive_times(chunk, accepted, decoder)
        alive = (np.concatenate((alive[0][-1:], status_s)),
                 np.concatenate((alive[1][-1:], count + np.searchsorted(enc.timestamp_s,
                                                                        status_s))))
        count, enc_t = count + len(g), np.concatenate((enc_t[-KEPT_TIMES:], enc.timestamp_s))
        from_e0 = g >= e0
        if from_e0.any():
            taken = _take(enc, from_e0)
            reference.feed(taken)
            if reference.last_steps is not None and len(taken.index):
                judge.feed_frames(g[from_e0], *reference.last_steps, taken.seq,
                                  reference.last_refused)
        twist.feed(chunk, accepted, enc)
    return judge.result()
