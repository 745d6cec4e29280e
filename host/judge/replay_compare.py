"""The replayed firmware's on-board poses against the logged ones (``host.judge.replay``'s
``onboard_vs_log`` section, and the departures that fail a replay).

At each encoder frame both firmwares' poses name, the largest difference between any pose sent
naming it in the log and in the replay: positions up to the log's first gap of the encoder
sequence, after it their offset's drift between two gaps (when the log says its firmware took
its frames on time, ``replayable``), headings everywhere, and the log's resent positions against
its first at the same frame (one firmware's poses at one frame agree). A half of the log whose
partner the bus lost is compared on what it carries, the same way (``replay_lone``). The
offset's jump across each gap (and, where the log's firmware merged frames on board, between
any two poses) is held to what the encoder counts either side allow (``replay_jumps``): a
re-anchoring at a gap is no free pass.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np
import numpy.typing as npt

from odocan.firmware.errors import ErrorFlag
from odocan.host.io.logs import FrameArrays
from odocan.host.judge.analysis import HEADING_LSB_RAD, POSITION_LSB_M, Tolerance
from odocan.host.judge.posehalves import BAM, HALVES
from odocan.host.judge.powerup import starts_at_power_up
from odocan.host.judge.replay_jumps import JumpModel, Jumps, LogSteps, offset_jumps
from odocan.host.judge.replay_late import boot_summaries, halves_sent_at
from odocan.host.judge.replay_lone import (
    Anchoring,
    LoneFigures,
    LoneHalves,
    turned,
    unpaired,
    versus_replay,
)
from odocan.host.judge.replay_track import EncoderTrack, crc_holds
from odocan.host.judge.samples import Poses
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e import check_frames
from odocan.sim import contract

IntArray = npt.NDArray[np.int64]
HOLE_CYCLES = 3  # no frame at all for longer than 3 encoder cycles: a hole of the log
SAID_HOLES = 3  # holes named one by one in the summary

Halves = dict[int, list[tuple[int, int]]]


def halves_by_tick(frames: FrameArrays, accepted: npt.NDArray[np.bool_]) -> tuple[Halves, Halves]:
    """The pose halves of ``frames`` (``posehalves.HALVES``) by the tick of the encoder frame
    they name: X and HEADING raw of each ODOM_POSE_X, Y and TURNS raw of each ODOM_POSE_Y; per
    tick the first sent naming it, then each other one sent naming it (a resend)."""
    decoder = BulkDecoder(contract.database())
    track = EncoderTrack.of(frames, accepted, decoder)
    kept = _kept_halves(frames, decoder)
    halves = []
    for (d, keep), (ticks, late), (_, value, extra) in zip(
            kept, _named_as_sent(frames, track, kept, boot_summaries(frames, decoder)), HALVES,
            strict=True):
        half: Halves = {}
        # a resend names its predecessor's frame (one naming an earlier one after a gap of the
        # log's frames is no resend); a late frame is no predecessor
        previous = -1
        for tick, v, e, was_late in zip(ticks.tolist(), d[value][keep].tolist(),
                                        d[extra][keep].tolist(), late.tolist(), strict=True):
            sent = half.setdefault(tick, []) if tick >= 0 else []
            if (not sent or tick == previous) and (int(v), int(e)) not in sent:
                sent.append((int(v), int(e)))
            previous = previous if was_late else tick
        halves.append(half)
    return halves[0], halves[1]


Kept = list[tuple[dict[str, Any], npt.NDArray[np.bool_]]]


def _kept_halves(frames: FrameArrays, decoder: BulkDecoder) -> Kept:
    """Each pose message of ``HALVES`` decoded, and which of its frames carry a right CRC
    (every pose sent, ``crc_holds``)."""
    kept = []
    for name, _, _ in HALVES:
        d = decoder.decode(frames, name)
        kept.append((d, crc_holds(frames, decoder, name, d["index"])))
    return kept


def _named_as_sent(frames: FrameArrays, track: EncoderTrack, kept: Kept,
                   boots: IntArray) -> list[tuple[IntArray, npt.NDArray[np.bool_]]]:
    """Per pose message of ``kept``: the tick each kept frame names, a late one's from where it
    was sent (``replay_late``, each half read with its partner), and which were late."""
    halves = [(d["index"][keep].astype(np.int64), d["COUNTER"][keep].astype(np.int64),
               d["ENC_COUNTER"][keep].astype(np.int64)) for d, keep in kept]
    return [(track.named(at, enc, at_s), at != rows) for (rows, _, enc), (at, at_s)
            in zip(halves, halves_sent_at(frames, track, halves, boots), strict=True)]


def paired(px: Halves, py: Halves) -> dict[int, list[tuple[int, int, int]]]:
    """The poses at the ticks both halves name: (X raw, Y raw, heading in BAM16 units unwrapped
    = TURNS * 65536 + HEADING); the first X with the first Y, then each other X and Y sent
    naming it (a resend: every pose frame is compared, each half with the first of the other
    kind, as ``host.judge.resent``)."""
    return {t: [(x, py[t][0][0], py[t][0][1] * BAM + h) for x, h in px[t]]
            + [(px[t][0][0], y, turns * BAM + px[t][0][1]) for y, turns in py[t][1:]]
            for t in px.keys() & py.keys()}


def onboard_by_tick(frames: FrameArrays, accepted: npt.NDArray[np.bool_]) -> dict[int, list[
        tuple[int, int, int]]]:
    """The on-board poses of ``frames`` by the tick of the encoder frame they name (``paired``
    of ``halves_by_tick``): a half whose partner was lost is not in it (``replay_lone``)."""
    return paired(*halves_by_tick(frames, accepted))


def x_pose_ticks(frames: FrameArrays, track: EncoderTrack, decoder: BulkDecoder) -> IntArray:
    """The tick of the encoder frame each ODOM_POSE_X frame with a right CRC names (-1: none
    the log's accepted encoder sequence places, ``EncoderTrack.named``): every pose the log's
    firmware sent, to say which were compared and why the others were not."""
    kept = _kept_halves(frames, decoder)
    return _named_as_sent(frames, track, kept, boot_summaries(frames, decoder))[0][0]


def versus_log(
    log: FrameArrays, log_accepted: npt.NDArray[np.bool_], replayed: FrameArrays,
    from_power_up: bool = False, jumps: JumpModel | None = None,
) -> dict[str, Any]:
    """The replayed on-board poses against the logged ones at the same encoder frames (at each,
    the largest difference between any pose sent naming it in the log and in the replay).

    Where the replay cannot live what the recording firmware lived, the comparison re-anchors:
    a log that starts mid-drive (``starts_mid_drive``: the replay starts from (0, 0, 0) on its
    first encoder frame) and after each hole of the log (``recorder_holes``: the recording
    firmware took frames the replay is not fed, e.g. a step its counters wrapped over), the
    heading offset at the first frame both name (``anchors``) is taken off the headings that
    follow, less one LSB of rounding, and the replayed positions are turned by it and compared
    by their drift (``drift_between_gaps_m``). ``max_position_diff_m`` is the position figure
    the verdict judges (the larger of the difference up to the first gap and the drift between
    gaps); ``max_position_diff_raw_m`` the raw difference over every pose, holes and all (None
    for a log cut mid-drive: its positions have no common origin). ``from_power_up``: the log
    is known to start at its firmware's power-up, where the replay's does too (a life
    ``replay_lives`` cut at it), so never mid-drive: its positions are compared as they are,
    whatever the cut's first poses look like (re-anchoring there would absorb an offset).
    ``jumps``: the robot's bound on the firmware's steps, to hold the offset's jump across each
    gap (or, where the log's firmware merged frames, between any two poses) to what the counts
    either side allow (``replay_jumps``; None: not compared)."""
    _, accepted = check_frames(replayed)
    px, py = halves_by_tick(log, log_accepted)
    old, new, lone = paired(px, py), onboard_by_tick(replayed, accepted), LoneHalves.of(px, py)
    common = np.array(sorted(old.keys() & new.keys()), dtype=np.int64)
    decoder = BulkDecoder(contract.database())
    track = EncoderTrack.of(log, log_accepted, decoder)
    mid = not from_power_up and starts_mid_drive(log, log_accepted, old, track)
    holes = recorder_holes(log)
    named = x_pose_ticks(log, track, decoder)
    facts: dict[str, Any] = {"logged": len(named), "log_starts_mid_drive": mid, "holes": holes,
                             "max_resent_position_diff_m": max(
                                 resent_position_diff_m(old), lone.resent_lsb * POSITION_LSB_M)}
    if len(common) == 0:
        return {"samples": 0, "identical": 0, "identical_before_gap": 0,
                "max_position_diff_m": None, "max_position_diff_raw_m": None,
                "max_heading_diff_rad": None, "before_first_gap": 0,
                "max_position_diff_before_gap_m": None, "heading_offsets_bam16": [],
                "max_position_drift_between_gaps_m": None, **facts,
                **_lone_facts(named, common, LoneFigures(not_compared=len(lone.tick)))}
    after = np.searchsorted(track.index, [int(h["before"]) for h in holes], "right")
    hole_ends = track.tick[after[after < len(track.tick)]]  # a hole ending the log: none
    turn, anchored, offsets = anchors(common, old, new, hole_ends, mid)
    position, heading, differs = _differences(common, old, new, turn, anchored)
    ticks = track.tick
    gaps = np.flatnonzero(np.diff(ticks) > 1)
    first_gap = int(ticks[gaps[0]]) if len(gaps) else int(ticks[-1])  # last tick before it
    before = 0 if mid else int(np.searchsorted(common, first_gap, side="right"))
    log_xy, replay_xy = (np.array([poses[t][0][:2] for t in common.tolist()], dtype=np.int64)
                         for poses in (old, new))
    gap_ends = np.r_[common[0], ticks[gaps + 1]] if mid else ticks[gaps + 1]
    drifts = replayable(log, log_accepted)
    alone = versus_replay(lone, new, Anchoring(
        common, hole_ends, turn, anchored, gap_ends,
        log_xy - turned(replay_xy, turn) if drifts else None, replay_xy,
        None if mid else first_gap))
    drift = _larger(drift_between_gaps_m(common, log_xy, replay_xy, gap_ends, turn, anchored),
                    alone.drift_m) if drifts else None
    before_gap = _larger(float(position[:before].max()) if before else None, alone.before_gap_m)
    jumped = Jumps() if jumps is None else offset_jumps(
        jumps, common, log_xy - turned(replay_xy, turn), turn, anchored, replay_xy,
        (LogSteps.of(log, log_accepted, track, not mid), None if drifts else
         LogSteps.of(replayed, accepted, EncoderTrack.of(replayed, accepted, decoder), not mid)))
    judged = [v for v in (before_gap, drift) if v is not None]
    return {
        "samples": len(common),
        "identical": int(np.count_nonzero(differs == 0)),
        "identical_before_gap": int(np.count_nonzero(differs[:before] == 0)),
        # the figure the verdict compares (``departures``), not the raw one across a hole
        "max_position_diff_m": max(judged) if judged else None,
        "max_position_diff_raw_m": None if mid else _larger(float(position.max()), alone.raw_m),
        "max_heading_diff_rad": _larger(float(heading.max()), alone.heading_rad),
        "before_first_gap": before,
        "max_position_diff_before_gap_m": before_gap,
        "heading_offsets_bam16": offsets,
        "max_position_drift_between_gaps_m": drift, **jumped.facts(),
        **facts, **_lone_facts(named, common, alone),
    }


def _larger(a: float | None, b: float | None) -> float | None:
    """The larger of two figures, either None when not measured."""
    return b if a is None else a if b is None else max(a, b)


def _lone_facts(named: IntArray, common: IntArray, alone: LoneFigures) -> dict[str, Any]:
    """The report's ``lone_halves`` (compared with the replay, and not) and ``not_compared``
    (the log's ODOM_POSE_X frames compared neither in a pair nor alone)."""
    return {"lone_halves": {"x": alone.x, "y": alone.y, "not_compared": alone.not_compared},
            "not_compared": {"unnamed": int(np.count_nonzero(named < 0)),
                             "unpaired": unpaired(named, common.tolist(), alone)}}


Poses3 = dict[int, list[tuple[int, int, int]]]


def anchors(common: IntArray, old: Poses3, new: Poses3, hole_ends: IntArray,
            mid: bool) -> tuple[IntArray, npt.NDArray[np.bool_], list[int]]:
    """At each ``common`` tick: the heading offset (log - replay, BAM16) taken off the replay's
    and whether it is an anchor's (measured on the bus: known to one LSB) rather than 0 by
    construction (a log from power-up, before its first hole); and every anchor's offset. A
    segment starts at the log's start and after each hole (``hole_ends``: the first tick after
    it); its anchor is its first common tick."""
    segment = np.searchsorted(hole_ends, common, side="right")
    starts = np.flatnonzero(np.r_[True, segment[1:] != segment[:-1]])
    anchored = segment > 0 if not mid else np.ones(len(common), dtype=np.bool_)
    offset = np.array([0 if not anchored[i] else
                       old[int(common[i])][0][2] - new[int(common[i])][0][2]
                       for i in starts.tolist()], dtype=np.int64)
    turn = offset[np.cumsum(np.r_[True, segment[1:] != segment[:-1]]) - 1]
    return turn, anchored, [int(o) for o, i in zip(offset, starts, strict=True) if anchored[i]]


def _differences(common: IntArray, old: Poses3, new: Poses3, turn: IntArray,
                 anchored: npt.NDArray[np.bool_]) -> tuple[npt.NDArray[np.float64], ...]:
    """Per common tick: the largest position difference (m, as they are), heading difference
    (rad, less its anchor's offset and, anchored, one LSB of rounding) and 1.0 where any pose
    pair differs at all."""
    pairs = [(t, a, b) for t in common.tolist() for a, b in itertools.product(old[t], new[t])]
    at = np.searchsorted(common, [t for t, _, _ in pairs])
    a = np.array([p[1] for p in pairs], dtype=np.int64)
    b = np.array([p[2] for p in pairs], dtype=np.int64)
    position, heading, differs = (np.zeros(len(common)) for _ in range(3))
    np.maximum.at(position, at, np.hypot(a[:, 0] - b[:, 0], a[:, 1] - b[:, 1]) * POSITION_LSB_M)
    beyond = np.maximum(np.abs(a[:, 2] - b[:, 2] - turn[at]) - anchored[at], 0)
    np.maximum.at(heading, at, beyond * HEADING_LSB_RAD)
    np.maximum.at(differs, at, (a != b).any(axis=1).astype(np.float64))
    return position, heading, differs


def starts_mid_drive(frames: FrameArrays, accepted: npt.NDArray[np.bool_],
                     poses: dict[int, list[tuple[int, int, int]]], track: EncoderTrack) -> bool:
    """The log does not start at its firmware's power-up (``powerup.starts_at_power_up``, the
    judges' rule): its poses are then off the replay's, which starts from (0, 0, 0) on the
    log's first encoder frame, by the pose the recording firmware had there."""
    if not poses:
        return False
    first = min(poses)
    x, y, h = poses[first][0]
    onboard = Poses(enc=np.array([int(np.searchsorted(track.tick, first))], dtype=np.int64),
                    x_m=np.array([x * POSITION_LSB_M]), y_m=np.array([y * POSITION_LSB_M]),
                    heading_rad=np.array([h * HEADING_LSB_RAD]),
                    heading_raw=np.array([h & 0xFFFF], dtype=np.int64))
    decoder = BulkDecoder(contract.database())
    return not starts_at_power_up(frames, accepted, decoder, onboard)


def recorder_holes(frames: FrameArrays) -> list[dict[str, float]]:
    """Where the log has no frame at all for more than ``HOLE_CYCLES`` encoder cycles (its
    recorder lost them, or the whole bus was silent): ``t_s`` the log's time before the hole
    (from its first frame) and ``length_s``. Across one the recording firmware may have had
    frames the replay is not fed, so its positions are compared only by their drift after.
    ``before``: the position of the log's last frame before it."""
    if len(frames) < 2:
        return []
    times = np.asarray(frames.timestamp_s, dtype=np.float64)
    step = np.diff(times)
    at = np.flatnonzero(step > HOLE_CYCLES * contract.cycle_time_s("WHEEL_ENCODERS"))
    return [{"t_s": round(float(times[i] - times[0]), 3), "length_s": round(float(step[i]), 3),
             "before": i} for i in at.tolist()]


def replayable(frames: FrameArrays, accepted: npt.NDArray[np.bool_]) -> bool:
    """True when the recording firmware took its encoder frames each on its tick, as far as the
    log tells: no ODOM_STATUS summary reports TIME_LOST or MAILBOX_OVERFLOW (frames merged on
    board). Else a drift between gaps is no departure. An encoder frame the host's E2E check
    refused (late, repeated) no longer makes a log unreplayable: the replay feeds it where it
    reached the recording firmware (``replay_track.late_frames``) and the replayed firmware's
    own check takes it or not, as the recording one did; counted here, every position of a log
    with one late frame went uncompared (``delay=0.3:50``: 125 of 126 poses)."""
    try:
        page = BulkDecoder(contract.database()).decode_page(frames, "ODOM_STATUS", 0)
    except DecodeError:
        return True
    masks = page["ERROR_MASK"][accepted[page["index"]]].astype(np.int64)
    return not (masks & (ErrorFlag.TIME_LOST | ErrorFlag.MAILBOX_OVERFLOW)).any()


def drift_between_gaps_m(
    common: IntArray, log_xy: IntArray, replay_xy: IntArray, gap_ends: IntArray,
    turn: IntArray | None = None, anchored: npt.NDArray[np.bool_] | None = None,
) -> float:
    """How far the logged and the replayed positions move apart between two gaps of the log's
    encoder sequence after its first (m; before it they are compared as they are): the offset
    (log - replay, raw LSB, at the ``common`` ticks; the replay's positions turned by ``turn``
    first, the heading offset of its anchor, ``anchors``) less its value at the first common
    tick of its segment (``gap_ends``: the first tick after each gap), less the rounding.
    Across a gap the recording firmware may have had frames the log lacks, so the offset may
    jump there; between gaps both firmwares take the same frames from the same heading (exact
    everywhere, up to the anchor's offset), so one firmware's offset stays put: on the bus,
    rounded to the LSB, within one LSB per axis of it; turned by an anchor's offset, known to
    one BAM16 LSB, within 2.5 LSB per axis (0.5 + 0.5 * sqrt 2, twice) plus that LSB's angle
    times the replay's travel since the segment's first tick."""
    if len(common) == 0:
        return 0.0
    loose = np.zeros(len(common), dtype=np.bool_) if anchored is None else anchored
    offset = log_xy - turned(replay_xy, np.zeros(len(common)) if turn is None else turn)
    segment = np.searchsorted(gap_ends, common, side="right")
    first = np.r_[True, segment[1:] != segment[:-1]]  # a segment's first common tick
    start = np.flatnonzero(first)[np.cumsum(first) - 1]
    travel = np.hypot(*(replay_xy - replay_xy[start]).T.astype(np.float64))
    rounding = np.where(loose, 2.5 + HEADING_LSB_RAD * travel, 1.0)[:, None]
    moved = np.maximum(np.abs(offset - offset[start]) - rounding, 0)[segment > 0]
    return float(np.hypot(moved[:, 0], moved[:, 1]).max(initial=0.0)) * POSITION_LSB_M


def resent_position_diff_m(poses: dict[int, list[tuple[int, int, int]]]) -> float:
    """The largest position difference between a pose resent naming an encoder frame and the
    first naming it, in one log (``onboard_by_tick``): across a gap the log's positions are not
    compared with the replay's, but one firmware's poses at one frame must agree anyway."""
    diff = [math.hypot(x - sent[0][0], y - sent[0][1])
            for sent in poses.values() for x, y, _ in sent[1:]]
    return max(diff, default=0.0) * POSITION_LSB_M


def departures(vs_log: dict[str, Any], tolerance: Tolerance) -> list[str]:
    """Why the replayed firmware departs from the recorded one (module docstring, "Verdict"):
    empty when it does not (or when the log has no on-board pose to compare with)."""
    reasons = []
    position = vs_log["max_position_diff_before_gap_m"]
    if position is not None and position > tolerance.position_m:
        reasons.append(f"its position differs from the log's by up to {position * 1e3:.4f} mm "
                       f"(tolerance {tolerance.position_m * 1e3:.4g} mm)")
    drift = vs_log.get("max_position_drift_between_gaps_m")
    if drift is not None and drift > tolerance.position_m:
        reasons.append(f"between gaps of the log its position moves off the log's by up to "
                       f"{drift * 1e3:.4f} mm (tolerance {tolerance.position_m * 1e3:.4g} mm)")
    jump = vs_log.get("max_position_jump_excess_m")
    if jump is not None and jump > tolerance.position_m:
        reasons.append(f"across a gap or stall of the log its position jumps off the log's by "
                       f"up to {jump * 1e3:.4f} mm more than the encoder counts either side "
                       f"allow (tolerance {tolerance.position_m * 1e3:.4g} mm)")
    resent = vs_log.get("max_resent_position_diff_m")
    if resent is not None and resent > tolerance.position_m:
        reasons.append(f"the log's resent positions differ from its first at the same encoder "
                       f"frame by up to {resent * 1e3:.4f} mm "
                       f"(tolerance {tolerance.position_m * 1e3:.4g} mm)")
    resume = vs_log.get("max_resume_excess_m")
    if resume is not None and resume > 0.0:
        reasons.append(f"after a stall its first pose lies {resume * 1e3:.4f} mm beyond any "
                       "its firmware can resume at from its pose before (stallresume: fine "
                       "steps to a frame its FIFO kept, one merged step, fine steps on)")
    kept = vs_log.get("max_position_diff_after_kept_stall_m")
    if kept is not None and kept > tolerance.position_m:
        reasons.append(f"after a stall it reproduced its position differs from the log's by up "
                       f"to {kept * 1e3:.4f} mm (tolerance {tolerance.position_m * 1e3:.4g} mm)")
    heading = vs_log["max_heading_diff_rad"]
    if heading is not None and heading > tolerance.heading_rad:
        reasons.append(f"its heading differs from the log's by up to {heading * 1e3:.4f} mrad "
                       f"(tolerance {tolerance.heading_rad * 1e3:.4g} mrad)")
    return reasons


def pose_phase_ticks(frames: FrameArrays, accepted: npt.NDArray[np.bool_],
                     until_tick: int | None = None) -> int:
    """The ticks the replay runs its firmware before the log's first encoder frame so that its
    poses name the encoder frames the log's name: the log's pose ticks (from its first encoder
    frame) mod the pose period, the most common (0 for a log from power-up; a log cut at an odd
    frame has its poses on odd ticks, and a replay out of phase has no frame in common). Only
    those before ``until_tick`` when given (the first life's: a firmware reset at an odd tick
    sends its poses on odd ticks from there, and a longer second life outvoted the first, whose
    poses the replay then named none of: UNJUDGED, exit 1, for a correct firmware)."""
    period = round(contract.cycle_time_s("ODOM_POSE_X") / contract.cycle_time_s("WHEEL_ENCODERS"))
    ticks = np.array(sorted(onboard_by_tick(frames, accepted)), dtype=np.int64)
    if until_tick is not None and (ticks < until_tick).any():
        ticks = ticks[ticks < until_tick]
    if period < 2 or len(ticks) == 0:
        return 0
    return int(np.bincount(ticks % period, minlength=period).argmax())


def compared(vs_log: dict[str, Any]) -> str:
    """What was compared with the log, in the words of the verdict (``departures``): a log from
    power-up without a gap, every pose as it is; else the positions up to the first gap as they
    are, after it (or all of them, from a log cut mid-drive) by their drift between gaps, and
    the headings less their offset at each anchor. Never the raw difference across a hole,
    which the verdict does not judge."""
    samples, before = int(vs_log["samples"]), int(vs_log["before_first_gap"])
    heading = f"{vs_log['max_heading_diff_rad'] * 1e3:.4f} mrad"
    if before == samples and not vs_log.get("log_starts_mid_drive"):
        return (f"{vs_log['identical']} identical, max difference "
                f"{vs_log['max_position_diff_m'] * 1e3:.4f} mm, {heading}{_lone_said(vs_log)}")
    parts = []
    if before:
        parts.append(f"{before} up to the log's first gap as they are "
                     f"({vs_log['identical_before_gap']} identical, max difference "
                     f"{vs_log['max_position_diff_before_gap_m'] * 1e3:.4f} mm)")
    where = (f"{samples - before} after it" if before
             else f"all {samples} of a log cut mid-drive")
    drift = vs_log.get("max_position_drift_between_gaps_m")
    parts.append(f"{where} by their position drift between gaps (max {drift * 1e3:.4f} mm)"
                 if drift is not None else
                 f"{where}: positions by their jumps between poses, held to what the counts "
                 "allow (the log's firmware did not take its frames on time)")
    anchored = bool(vs_log.get("heading_offsets_bam16"))
    parts.append(f"heading {heading}" + (" less its offset where re-anchored" if anchored else ""))
    return "; ".join(parts) + _lone_said(vs_log)


def _lone_said(vs_log: dict[str, Any]) -> str:
    """The lone halves compared (``replay_lone``), in the words of ``compared``: none, nothing."""
    lone = vs_log.get("lone_halves") or {}
    x, y = int(lone.get("x", 0)), int(lone.get("y", 0))
    if not x and not y:
        return ""
    return (f"; {x + y} lone pose halves ({x} ODOM_POSE_X, {y} ODOM_POSE_Y: their partner lost) "
            "compared on what they carry, as the pairs")


def not_comparable(vs_log: dict[str, Any]) -> list[str]:
    """What the comparison with the log could not reproduce, in words: the poses not compared
    and why, a start mid-drive, and each hole of the log (the first ``SAID_HOLES``, then how
    many more)."""
    lines = []
    left = vs_log.get("not_compared") or {}
    if left.get("unnamed") or left.get("unpaired"):
        lines.append(f"{left['unnamed'] + left['unpaired']} of the log's {vs_log['logged']} "
                     f"ODOM_POSE_X frames not compared: {left['unnamed']} name an encoder frame "
                     "the log's E2E-accepted sequence cannot place (late, refused or lost), "
                     f"{left['unpaired']} one the replayed firmware sent no pose for")
    alone = int((vs_log.get("lone_halves") or {}).get("not_compared", 0))
    if alone:
        lines.append(f"{alone} lone pose halves (their partner lost) not compared: the replayed "
                     "firmware sent no pose for the frame they name, or no pose both halves "
                     "name anchors their stretch of the log")
    drift = vs_log.get("max_position_drift_between_gaps_m") is not None
    if vs_log.get("log_starts_mid_drive"):
        offset = (vs_log.get("heading_offsets_bam16") or [0])[0] * HEADING_LSB_RAD
        lines.append("the log starts mid-drive, not at its firmware's power-up: the replayed "
                     "firmware starts from (0, 0, 0) on the log's first encoder frame, so its "
                     "headings are compared less the log's offset at the first frame both "
                     f"name ({offset:.4f} rad), "
                     + ("its positions by their drift, turned by that offset" if drift else
                        "its positions by their jumps, held to what the counts allow (the "
                        "log's firmware did not take its frames on time)"))
    holes = vs_log.get("holes") or []
    for hole in holes[:SAID_HOLES]:
        lines.append(f"the log has a hole at t={hole['t_s']:.2f} s ({hole['length_s']:.2f} s "
                     "without a frame): the recording firmware took frames there the replay "
                     "is not fed, so its poses are not comparable as they are after it: "
                     "headings are compared less their offset at the first frame both name "
                     "after it, " + ("positions by their drift between gaps" if drift else
                                     "positions by their jumps") + ", their jump across it "
                     "held to what the encoder counts either side allow")
    if len(holes) > SAID_HOLES:
        lines.append(f"... and {len(holes) - SAID_HOLES} more holes")
    return lines


def unjudged(vs_log: dict[str, Any]) -> str | None:
    """Why a replay compared nothing although the log has on-board poses (a verdict no CI may
    take for a PASS: exit 1), else None (a log without poses has nothing to compare: the
    replay is judged against its float64 reference alone)."""
    if vs_log["samples"] or not vs_log.get("logged"):
        return None
    return (f"UNJUDGED: none of the log's {vs_log['logged']} on-board poses could be paired "
            "with the replayed firmware's (by the encoder frame each names): the replay was not "
            "compared with the firmware that recorded the log")
