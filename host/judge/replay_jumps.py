"""How far the logged positions may jump off the replayed ones across a gap or a stall (issue
#11, rule 5: a PASS must never hide a wrong pose).

Between two gaps of the log's encoder sequence both firmwares take the same frames from the
same heading, so the offset log - replay stays put (``replay_compare.drift_between_gaps_m``).
Across a gap it may move, but not freely: the recording firmware may have taken frames there
the log lacks, yet the encoder counts either side give each wheel's travel across it exactly
(mod the wire counter's width), and every step it took is within the plausibility bound per
encoder period. So its position after the gap lies within ``gapbound.gap_allowance_m`` (the
worst split of the merged step into the gap's periods, the analysis judge's bound) of the one
merged step the replayed firmware took there. The offset's jump between the last pose both
name before a gap and the first after it is held to the sum of its gaps' allowances.

Where the log says its firmware merged frames on board (a stall: TIME_LOST or
MAILBOX_OVERFLOW, ``replay_compare.replayable`` False) any two poses may have been reached by
different steps, so every jump between two consecutive poses both name is held to what each
firmware's steps may have done differently from the log's frames there, where before nothing
was compared after the first gap: for a firmware whose pages prove it took exactly the log's
frames (``gapseen``), the gaps' allowances above; else, where its steps are runs of the log's
frames (the replay's always; the recording one's where no gap lies between or its pages prove
it missed each), the worst merge error of such runs (``breaks.merge_allowance_m``, the analysis
judge's stall bound); else the gap allowance of the whole span.

Rounding: each pose on the bus is within half an LSB per axis of its firmware's, so a jump of
the offset within 2 LSB per axis; turned by an anchor's heading offset (``anchors``), the drift
check's 2.5 LSB plus that LSB's angle times the replay's travel. A pair across two anchors
(the heading offset changed at a hole of the log) is not compared.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from odocan.firmware.encoders import WIRE_COUNTER_BITS
from odocan.host.io.logs import FrameArrays
from odocan.host.judge.analysis import HEADING_LSB_RAD, POSITION_LSB_M
from odocan.host.judge.breaks import merge_allowance_m
from odocan.host.judge.gapbound import gap_allowance_of_counts
from odocan.host.judge.gapreceived import received_allowance_m, received_fill
from odocan.host.judge.gapseen import NOTHING, Seen, seen_in_log
from odocan.host.judge.reference import PROFILE_SPEED, Geometry
from odocan.host.judge.replay_track import MAX_GAP_TICKS, EncoderTrack
from odocan.host.judge.samples import encoder_frames
from odocan.host.protocol.decode import BulkDecoder
from odocan.sim import contract
from odocan.sim.robot import RobotProfile

IntArray = npt.NDArray[np.int64]
ROUNDING_LSB = 2.0  # per axis, a jump of the offset between two poses (four roundings)
ANCHORED_LSB = 2.5  # per axis, turned by an anchor's offset (``drift_between_gaps_m``)


@dataclass(frozen=True)
class JumpModel:
    """What bounds the recording firmware's steps: the robot's geometry and plausibility bound,
    the wire counter's width and the integrator."""

    geometry: Geometry
    bits: int
    integrator: str
    # the bus times [from, to] between which the replayed firmware was bus-off, hearing nothing
    # (``replay_deaf``), as the recording one (``replay_sent.bus_off_silences``)
    deaf_s: tuple[tuple[float, float], ...] = ()

    @classmethod
    def of(cls, robot: RobotProfile, integrator: str) -> JumpModel:
        return cls(Geometry.of(robot), min(robot.counter_bits, WIRE_COUNTER_BITS), integrator)

    def deaf_through(self, before_s: float, after_s: float, period_s: float) -> bool:
        """Every frame a gap between frames logged at ``before_s`` and ``after_s`` may have
        lost came while the firmware was bus-off (``deaf_s``): it heard none of them, so it
        took the gap as the replay's one merged step, as a firmware whose pages prove it missed
        the gap whole (its slots within half a period of the bus-off). Without this the jump
        across a bus-off's hole was held to the gap bound of its 32 periods: kobuki random 516,
        10 s, ``busoff=4.0:0.3``, ODOM_POSE_X raised 10 mm from the first pose after it
        PASSed within 121.8 mm."""
        return any(before_s + 1.5 * period_s >= start_s and after_s - 0.5 * period_s <= end_s
                   for start_s, end_s in self.deaf_s)

    def allowance_m(self, before: tuple[int, int], after: tuple[int, int], periods: int) -> float:
        """``gap_allowance_of_counts`` from wire counts ``before`` to ``after`` (inf: a gap
        the replay shortened, whose periods are not known)."""
        if periods >= MAX_GAP_TICKS:
            return math.inf
        return gap_allowance_of_counts(before, after, periods, self.geometry, self.bits,
                                       self.integrator, PROFILE_SPEED)


    def merge_m(self, counts: IntArray) -> float:
        """``breaks.merge_allowance_m`` of the frames with wire ``counts`` (n x 2): the worst
        merge error of a firmware whose steps are runs of them."""
        return merge_allowance_m(counts[:, 0], counts[:, 1], self.geometry, self.bits,
                                 self.integrator)


@dataclass(frozen=True)
class Jumps:
    """The offsets' jumps across gaps: the largest beyond its allowance (m), the largest
    allowance of a pair compared (m), and how many pairs were compared."""

    excess_m: float = 0.0
    allowance_m: float = 0.0
    pairs: int = 0

    def facts(self) -> dict[str, Any]:
        return {"max_position_jump_excess_m": self.excess_m,
                "max_jump_allowance_m": self.allowance_m, "jumps_compared": self.pairs}


@dataclass(frozen=True)
class LogSteps:
    """What the log tells of its encoder frames: ``track``'s wire counts (n x 2), and what the
    firmware's E2E pages prove it took (``gapseen.Seen``, its frames numbered by ``enc``
    position: ``enc_at``, per frame of ``track``)."""

    track: EncoderTrack
    counts: IntArray
    seen: Seen
    enc_at: IntArray

    @classmethod
    def of(cls, frames: FrameArrays, accepted: npt.NDArray[np.bool_], track: EncoderTrack,
           power_up: bool) -> LogSteps:
        decoder = BulkDecoder(contract.database())
        d = decoder.decode(frames, "WHEEL_ENCODERS")
        at = np.searchsorted(d["index"], track.index)
        counts = np.c_[d["LEFT_COUNT"][at], d["RIGHT_COUNT"][at]].astype(np.int64)
        enc = encoder_frames(frames, accepted, decoder)
        enc_at = np.searchsorted(enc.index, track.index)
        if len(enc.index) != len(track.index) or (enc.index[enc_at] != track.index).any():
            return cls(track, counts, NOTHING, enc_at)  # numbered otherwise: no evidence
        return cls(track, counts, seen_in_log(frames, decoder, enc, power_up=power_up), enc_at)

    def gap_missed(self, after: int) -> bool:
        """The firmware missed every frame of the gap into ``track``'s frame ``after`` (its
        pages prove it): it took the gap as the replay's one merged step."""
        return self.seen.gap_missed(int(self.enc_at[after]))

    def took_all(self, first: int, last: int) -> bool:
        """The firmware took exactly the log's frames ``first`` .. ``last`` (of ``track``)."""
        return self.seen.took_all(int(self.enc_at[first]), int(self.enc_at[last]))

    def gap_m(self, model: JumpModel, after: int, periods: int) -> float:
        """The allowance (m) of the gap into ``track``'s frame ``after`` of ``periods``:
        ``gapbound``'s, or ``gapreceived``'s where its pages prove the firmware received none
        of the frames the log lacks there."""
        before, now = _pair(self.counts[after - 1]), _pair(self.counts[after])
        return min(model.allowance_m(before, now, periods), received_allowance_m(
            received_fill(self.seen, int(self.enc_at[after])), before, now, periods,
            model.geometry, model.bits, model.integrator, PROFILE_SPEED))


def offset_jumps(model: JumpModel, common: IntArray, offset: npt.NDArray[np.float64],
                 turn: IntArray, anchored: npt.NDArray[np.bool_], replay_xy: IntArray,
                 steps: tuple[LogSteps, LogSteps | None]) -> Jumps:
    """Each jump of ``offset`` (log - turned replay, raw LSB, at the ``common`` ticks) between
    two consecutive common ticks against its allowance (module docstring). ``steps``: the log's,
    and the replayed bus's where the recording firmware may have merged frames anywhere (None:
    it did not; only pairs across a gap of the log's track are compared)."""
    excess, largest, pairs = 0.0, 0.0, 0
    at = [np.searchsorted(s.track.tick, common) for s in steps if s is not None]
    for i in range(1, len(common)):
        if turn[i] != turn[i - 1]:
            continue
        allow = _pair_allowance_m(model, steps, [(int(p[i - 1]), int(p[i])) for p in at])
        if allow is None or not math.isfinite(allow):
            continue
        step = offset[i] - offset[i - 1]
        loose = bool(anchored[i])
        travel = math.hypot(*(replay_xy[i] - replay_xy[i - 1]).astype(np.float64))
        slack = (ANCHORED_LSB + HEADING_LSB_RAD * travel) if loose else ROUNDING_LSB
        beyond = np.maximum(np.abs(step) - slack, 0.0)
        jump_m = float(np.hypot(beyond[0], beyond[1])) * POSITION_LSB_M
        excess = max(excess, jump_m - allow)
        largest, pairs = max(largest, allow), pairs + 1
    return Jumps(excess, largest, pairs)


def _pair_allowance_m(model: JumpModel, steps: tuple[LogSteps, LogSteps | None],
                      ends: list[tuple[int, int]]) -> float | None:
    """The allowance (m) of the jump between two poses naming the log's frames at ``ends[0]``
    (positions in its track; ``ends[1]`` in the replayed bus's): None when nothing can differ
    there (no gap, nothing merged). Each gap between counts its ``gapbound`` allowance, none
    where the firmware's E2E pages prove it missed the gap whole, as the replay did
    (``gapseen``). Where either firmware may have merged frames, it adds the allowance of the
    whole span unless its pages prove it took exactly the log's frames there."""
    log, replayed = steps
    a, b = ends[0]
    ticks, counts = log.track.tick[a:b + 1], log.counts
    gaps = np.flatnonzero(np.diff(ticks) > 1)
    times, period_s = log.track.timestamp_s, log.track.cycle_s or 0.0
    across = sum(0.0 if log.gap_missed(a + g + 1) or model.deaf_through(
        float(times[a + g]), float(times[a + g + 1]), period_s) else
                 log.gap_m(model, a + g + 1, int(ticks[g + 1] - ticks[g])) for g in gaps.tolist())
    if replayed is None:
        return across if len(gaps) else None
    runs = model.merge_m(counts[a:b + 1])  # steps of runs of the log's frames
    seen = all(log.gap_missed(a + g + 1) for g in gaps.tolist())
    periods = int(ticks[-1] - ticks[0])
    whole = runs if seen else model.allowance_m(_pair(counts[a]), _pair(counts[b]), periods)
    own = across if log.took_all(a, b) else whole
    return own + (0.0 if replayed.took_all(*ends[1]) else runs)


def _pair(row: IntArray) -> tuple[int, int]:
    return int(row[0]), int(row[1])
