"""``odocan analyze`` of a log file in bounded memory (issue #14.1): the report of
``host.judge.analysis.analyze`` (without the plot and export series), from the log read chunk
by chunk (``host.io.logs.iter_log``) in passes, each stage's state carried across chunks
(``host.judge.stream`` and the modules beside it), so that the report is the whole log's at
any chunk size (tests/test_stream_report.py).

Passes: the whole log once (E2E, the firmware lives, the report's facts); then per life:
1. E2E, encoder sequence, samples after stalls and holds, truth, twist, facts, the spans where
   the firmware lost encoder frames the log holds (``stream_losses.StreamLosses``) -> the start
   frame e0 (power-up or the first sample's), the stalls' breaks;
2. (and 3, 4 when the heading samples agree) the start pose (``stream_place.start_pose``);
5. the segment offsets, and the lossy spans' weights (``stream_losses.SpanDrops``); 6. the errors
   against the reference (and beyond the loss allowance) and the truth, the distance, the events'
   times. Memory: the chunk and the stages' carried state, never the log.
A life whose frames came in a burst after a busy bus is refused (``NotStreamable``:
``samples._queued`` pairs them by the whole life's median send period). Lives are cut again at
the applied set-poses and configs (``stream_cuts``), as the whole log's judge cuts them. A
power-up primed late (the first count page's k >= 1) is judged from each frame it may have
primed on, the life streamed again per candidate (``stream_primed``, from its first frames).
A stall the firmware declared it re-primed after (``stallreprime``) takes one pass more before
step 2, which holds a few frames around each stall (``stream_reprime``): the placing passes then
leave out the steps its re-prime left out. ``streams`` says when to stream at all."""

from __future__ import annotations

import functools
import tempfile
from collections.abc import Callable, Iterator
from contextlib import closing
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from odocan.host.io.frames import concat_frames
from odocan.host.io.logs import CHUNK_FRAMES, FrameArrays, iter_log, read_log, warn_on_stderr
from odocan.host.judge import acrosscut, e2estepbound, namesahead, stallrestart
from odocan.host.judge.analysis import Tolerance, analyze
from odocan.host.judge.breaks import placed_offsets
from odocan.host.judge.configs import ConfigPages, in_force
from odocan.host.judge.distance import DistanceJudge
from odocan.host.judge.gapfill import gap_or_fill_allowance
from odocan.host.judge.gapreceived import received_allowance_m, received_fill
from odocan.host.judge.gapskips import SkipCounts, took_none
from odocan.host.judge.judgedfloor import mark_floor
from odocan.host.judge.keptmark import mark_kept
from odocan.host.judge.nearthreshold import least_of
from odocan.host.judge.posestreams import PoseStreams
from odocan.host.judge.reboots import Life, merge
from odocan.host.judge.reference import PROFILE_SPEED, Geometry, SpeedBound
from odocan.host.judge.reportfacts import realtime, robot_dict
from odocan.host.judge.samples import (
    WIRE_COUNTER_BITS,
    AnalysisError,
    Encoders,
    require_messages,
)
from odocan.host.judge.setposekept import Kept, check_cut
from odocan.host.judge.stallfirst import STALL_DETAIL
from odocan.host.judge.stallreprime import detail as reprime_detail
from odocan.host.judge.stream import StreamE2E
from odocan.host.judge.stream_carry import CarriedSpans, carried
from odocan.host.judge.stream_choice import RSS_MARGIN as RSS_MARGIN
from odocan.host.judge.stream_choice import RSS_TARGET_MB as RSS_TARGET_MB
from odocan.host.judge.stream_choice import STREAM_MODES as STREAM_MODES
from odocan.host.judge.stream_choice import WHOLE_RSS_MB as WHOLE_RSS_MB
from odocan.host.judge.stream_choice import stream_above_bytes as stream_above_bytes
from odocan.host.judge.stream_choice import streams as streams
from odocan.host.judge.stream_compare import TruthCompare
from odocan.host.judge.stream_cuts import (
    StreamCuts,
    cut_spans,
    first_integrator,
    latched_per_firmware,
)
from odocan.host.judge.stream_distance import stream_distance
from odocan.host.judge.stream_facts import StreamFacts
from odocan.host.judge.stream_first import FirstPass, Frames, first_pass
from odocan.host.judge.stream_life import LifeInfo, life_chunks
from odocan.host.judge.stream_lives import LifeSpan, StreamLives
from odocan.host.judge.stream_losses import SpanDrops
from odocan.host.judge.stream_place import PlacedChunk, reference_errors, segment_offsets
from odocan.host.judge.stream_place import start_pose as place_start
from odocan.host.judge.stream_primed import cut_frames, judged_from_candidates
from odocan.host.judge.stream_refusal import UNSETTLED, NamesAhead
from odocan.host.judge.stream_refusal import NotStreamable as NotStreamable
from odocan.host.judge.stream_reprime import stream_reprimes
from odocan.host.judge.stream_spill import FrameSpill
from odocan.host.judge.stream_stallfirst import stream_first
from odocan.host.judge.stream_stalls import StreamBreakCounts
from odocan.host.judge.twosenders import LogSenders
from odocan.host.judge.unseenrestart import restart_detail, whole_only
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import UNKNOWN
from odocan.host.protocol.pose import heading_fields
from odocan.sim.robot import RobotProfile

if TYPE_CHECKING:  # a cantools Database or a plan of it (host.protocol.dbcplan)
    from odocan.host.protocol.dbcplan import DatabaseSpec

DEFAULT_TOLERANCE = Tolerance()


@dataclass
class FrameCount:
    """How many frames ``analyze_file`` read from the log (filled in as it reads)."""

    frames: int = 0


@e2estepbound.bounded  # the robot's step bound for the E2E checks' skip proofs (e2e_bound)
def analyze_file(
    path: str | Path,
    robot: RobotProfile,
    integrator: str | None = None,
    *,
    tolerance: Tolerance = DEFAULT_TOLERANCE,
    db: DatabaseSpec | None = None,
    scenario: str | None = None,
    seed: int | None = None,
    wall_seconds: float | None = None,
    max_wheel_speed_mm_s: SpeedBound = PROFILE_SPEED,
    chunk_frames: int = CHUNK_FRAMES,
    warn: Callable[[str], None] = warn_on_stderr,
    count: FrameCount | None = None,
    whole_on_config: bool = False,
    config_pages: ConfigPages | None = None,
    whole_on_ahead: bool = True,
) -> dict[str, Any]:
    """``analyze(read_log(path), ...).report``, the log read ``chunk_frames`` at a time
    (``warn``: where ``iter_log`` says it skipped a partial last line; ``count``, when given:
    the number of frames in the log, counted as they are read). ``whole_on_config``:
    ``NotStreamable`` when a config was applied (the CLI's PROFILE-page checks, which read
    the whole log: ``configs.running_before_configs``, ``later_mismatches``), unless
    ``config_pages`` reads them from the frames spilled (the robot then judged with its bound
    before the first config's APPLY, as the whole log's path). ``whole_on_ahead``: a life with
    a pose naming an encoder frame after those heard before it (``aheadnamed``: judged at the
    frames it may name, around it in the whole log) gives the whole log's report, the log read
    whole as the CLI reads a log the stream refused (no config applied); False: ``NamesAhead``
    (the CLI says so under ``--stream always`` and reads it whole itself)."""
    db = db if db is not None else default_plan()
    count = count if count is not None else FrameCount()
    decoder = BulkDecoder(db)
    require_messages(decoder)
    with tempfile.TemporaryDirectory(prefix="odocan-analyze-") as tmp:
        spill = FrameSpill(Path(tmp))
        e2e, lives = StreamE2E(db), StreamLives(decoder)  # one decoder: its cache too
        facts, cuts = StreamFacts(decoder), StreamCuts(decoder)
        senders = LogSenders(db)  # two tools on a command message (#11)
        streams, ahead = PoseStreams(db), namesahead.AheadScan(decoder)  # two firmwares (#11)
        with closing(spill):  # closed too when a bad line refuses the log mid-read
            for chunk in carried(iter_log(path, chunk_frames=chunk_frames, warn=warn), db):
                count.frames += len(chunk)
                spill.write(chunk)
                accepted = e2e.feed(chunk)
                lives.feed(chunk, accepted)
                facts.feed(chunk, accepted)
                cuts.feed(chunk, accepted)
                senders.feed(chunk)
                streams.feed(chunk)
                ahead.feed(chunk, accepted)
        if not e2e.exact:  # its accepted frames may not be the whole log's: nor its lives
            raise NotStreamable(UNSETTLED)

        carry = CarriedSpans(db)  # each life read in the passes: its cuts found once

        def frames_of(span: LifeSpan) -> Frames:
            return lambda: carry.chunks((span.start, span.stop), lambda: spill.read(
                span.start, span.stop, chunk_frames))

        firmware = lives.finish_one_source(streams.told())  # two firmwares: a FAIL from there
        applied = cuts.configs(robot.counter_bits, firmware)
        if applied and whole_on_config and config_pages is None:
            raise NotStreamable("a config was applied: its PROFILE pages are judged whole")
        if applied and config_pages is not None:
            robot = config_pages.read(applied, lambda lo, hi: spill.read(lo, hi, chunk_frames),
                                      count.frames)
        spans = cut_spans(firmware, cuts.set_poses(firmware), applied)
        try:
            report = _analyze_lives(
                spans, facts, frames_of, robot, integrator, tolerance=tolerance, db=db,
                scenario=scenario, seed=seed, wall_seconds=wall_seconds,
                max_wheel_speed_mm_s=max_wheel_speed_mm_s)
        except NamesAhead:
            if not whole_on_ahead or applied:
                raise
            return analyze(read_log(path, warn=_said_already), robot, integrator,
                           tolerance=tolerance, db=db, scenario=scenario, seed=seed,
                           wall_seconds=wall_seconds,
                           max_wheel_speed_mm_s=max_wheel_speed_mm_s).report
        if len(spans) != len(firmware):  # a set-pose is no reboot: one latch per firmware
            report.update(latched_per_firmware(firmware, frames_of, db))
        report["events"] = [*report.get("events", []), *senders.events]
        return namesahead.mark(mark_floor(lives.marked(report, count.frames)), ahead)  # judgedfloor


def _analyze_lives(
    spans: list[LifeSpan], facts: StreamFacts, frames_of: Callable[[LifeSpan], Frames],
    robot: RobotProfile, integrator: str | None, *, tolerance: Tolerance,
    db: DatabaseSpec, scenario: str | None, seed: int | None,
    wall_seconds: float | None, max_wheel_speed_mm_s: SpeedBound,
) -> dict[str, Any]:
    """``analysis.analyze`` over the lives found (``frames_of``: a life's frames, each call
    from its first)."""

    if len(spans) == 1:
        return _life(frames_of(spans[0]), robot, integrator, tolerance=tolerance, db=db,
                     boot=False, scenario=scenario, seed=seed, wall_seconds=wall_seconds,
                     max_wheel_speed_mm_s=max_wheel_speed_mm_s)[0]
    integrator, source = facts.integrator(integrator)
    done: list[tuple[LifeSpan, dict[str, Any], float]] = []
    failure: AnalysisError | None = None
    silent: list[Life] = []
    kept: dict[int, Kept] = {}  # per set-pose's life: what it kept (setposekept)

    def read(lo: int, hi: int) -> FrameArrays:
        return concat_frames(list(frames_of(LifeSpan(lo, hi, False))()))

    for k, (span, (life_robot, life_integrator, bound)) in enumerate(zip(spans, in_force(
            [_as_life(span) for span in spans], robot,
            first_integrator(spans, frames_of, db, integrator, source), max_wheel_speed_mm_s),
            strict=True)):
        if k and (span.set_pose is not None or span.config is not None) and acrosscut.backlog_in(
                read(max(spans[k - 1].start, span.start - acrosscut.WINDOW_FRAMES),
                     min(span.stop, span.start + acrosscut.WINDOW_FRAMES)), db,
                span.start - max(spans[k - 1].start, span.start - acrosscut.WINDOW_FRAMES)):
            raise NotStreamable(acrosscut.STREAM)
        try:
            report, t_first = _life(frames_of(span), life_robot, life_integrator,
                                    tolerance=tolerance, db=db, boot=span.boot,
                                    rebase=span.t_s is not None and span.config is None,
                                    max_wheel_speed_mm_s=bound,
                                    start_pose=span.set_pose and span.set_pose.start_pose(),
                                    silent=span.silent)
        except AnalysisError as exc:  # a life without on-board samples: reported, not compared
            failure = failure or exc
            silent.append(_as_life(span))
            continue
        if span.set_pose is not None:
            kept[len(done)] = check_cut(
                read, (spans[k - 1].start, spans[k - 1].boot), span.stop, span.set_pose, life_robot,
                life_integrator, db, bound)
        done.append((span, report, t_first))
    if not done:
        assert failure is not None
        raise failure
    report, _ = merge([d[1] for d in done], [{} for _ in done], [_as_life(d[0]) for d in done],
                      [d[2] for d in done], silent=silent)
    covered_s = facts.covered_s()
    report.update(
        integrator_source=source, scenario=scenario, seed=seed, sim_seconds=covered_s,
        first_frame_s=facts.first_frame_s, wall_seconds=wall_seconds,
        realtime_factor=realtime(covered_s, wall_seconds), frames=facts.frame_counts,
    )
    vs_ref = report["onboard_vs_reference"]
    report["passed"] = bool(
        vs_ref["max_position_error_m"] is not None
        and all(d[1]["passed"] for d in done)  # each life within its tolerance and allowance
        and vs_ref["max_heading_error_rad"] <= tolerance.heading_rad
        and report["onboard_twist_vs_reference"]["passed"]
        and report["onboard_distance_vs_reference"]["passed"]
    )
    mark_kept(report, kept)  # a set-pose that changed a field it kept: FAIL
    return report


def _drained(chunks: Iterator[Any]) -> None:
    """Run a pass for what it tells on the way (``stream_reprime.ReprimeTap``)."""
    for _ in chunks:
        pass


def _as_life(span: LifeSpan) -> Life:
    """A ``reboots.Life`` for ``merge`` (which reads its time and UPTIME, not its frames)."""
    return Life(np.zeros(0, dtype=np.int64), span.boot, span.t_s, span.uptime_before_s,
                set_pose=span.set_pose, config=span.config)


def _life(
    frames: Frames, robot: RobotProfile, integrator: str | None, *, tolerance: Tolerance,
    db: DatabaseSpec, boot: bool, max_wheel_speed_mm_s: SpeedBound,
    rebase: bool = False, scenario: str | None = None, seed: int | None = None,
    wall_seconds: float | None = None, start_pose: tuple[float, float, float] | None = None,
    silent: bool = False,
) -> tuple[dict[str, Any], float]:
    """``analysis._analyze_life``'s report of one life, and its first frame's time
    (``start_pose``: a set-pose's, exact at the life's first encoder frame)."""
    first = first_pass(frames, db, robot)
    first.refuse()
    facts, given = first.facts, integrator
    integrator, source = facts.integrator(integrator)
    first.check()
    power_up = not silent and (facts.saw_only_the_log() if boot
                               else facts.starts_at_power_up(first.head))
    judge = functools.partial(
        _judged, first, frames, robot, (integrator, source), power_up, tolerance=tolerance,
        db=db, max_wheel_speed_mm_s=max_wheel_speed_mm_s, rebase=rebase, scenario=scenario,
        seed=seed, wall_seconds=wall_seconds)
    if silent and start_pose is None:  # rebooted unheard: (0, 0, 0) on each frame (silentboot)
        event = first.prefix.silent_event(first.first_sent_s, first.head, (robot, integrator))
        counts = first.e2e.counts  # the frames before a cut counted all the same (primedon)
        whole = {"frames": facts.frame_counts, "unknown_frames": counts[UNKNOWN],
                 "e2e": {name: c for name, c in counts.items() if name != UNKNOWN}}
        if event:
            return judged_from_candidates(event, lambda pose, cut: judge(start_pose=pose) if (
                cut is None) else _life(
                    cut_frames(frames, cut), robot, given, tolerance=tolerance, db=db,
                    boot=boot, max_wheel_speed_mm_s=max_wheel_speed_mm_s, rebase=rebase,
                    scenario=scenario, seed=seed, wall_seconds=wall_seconds, start_pose=pose,
                    silent=True), (whole, first.t_first_s))
    if not (boot or rebase or power_up or start_pose is not None) and facts.primed_late():
        event = first.prefix.event(first.first_sent_s, (robot, integrator))  # stream_primed
        if event:  # judged from each frame it may have primed on, as the whole log's judge
            return judged_from_candidates(event, lambda pose, _: judge(start_pose=pose))
    return judge(start_pose=start_pose)


def _judged(
    first: FirstPass, frames: Frames, robot: RobotProfile, integrators: tuple[str, str],
    power_up: bool, *, tolerance: Tolerance, db: DatabaseSpec,
    max_wheel_speed_mm_s: SpeedBound, rebase: bool, scenario: str | None, seed: int | None,
    wall_seconds: float | None, start_pose: tuple[float, float, float] | None,
) -> tuple[dict[str, Any], float]:
    """``_life``'s report from its first pass (``first``; ``integrators``: the integrator and
    its source; ``start_pose``: a set-pose's or a candidate priming frame's, exact at the
    life's first encoder frame)."""
    integrator, source = integrators
    facts = first.facts
    at_first = power_up or start_pose is not None  # the start exact at the first frame
    e0 = 0 if at_first else int(first.head.enc[0])
    breaks = first.breaks
    spans = first.losses.spans(power_up and start_pose is None)
    geometry, bits = Geometry.of(robot), min(robot.counter_bits, WIRE_COUNTER_BITS)
    seen_all = first.pages.seen(power_up)
    stalled = stream_reprimes(  # a stall it declared it re-primed after: stream_reprime
        lambda tap: _drained(life_chunks(frames(), db, robot, integrator, e0=e0, breaks=breaks,
                                         max_wheel_speed_mm_s=max_wheel_speed_mm_s, tap=tap)),
        BulkDecoder(db), breaks.tolist(), e0, seen_all.resets,
        least_of(geometry, bits, max_wheel_speed_mm_s),
        start_pose if start_pose is not None else (0.0, 0.0, 0.0) if power_up else None,
        (geometry, bits, integrator))
    drops = SpanDrops(spans, geometry, bits, integrator,  # losses.life_placements
                      [b for b in breaks.tolist() if b > e0 and b - e0 not in stalled.reprimes])
    across = StreamBreakCounts(breaks[breaks > e0].tolist(), geometry, bits, integrator,
                               max_wheel_speed_mm_s)

    skips = SkipCounts(seen_all.skips)  # gapskips: the frames around a gap it received

    def on_encoders(enc: Encoders) -> None:
        drops.feed(enc)
        across.feed(enc)
        skips.feed(enc)

    def placed(info: LifeInfo | None = None, losses: bool = False) -> Iterator[PlacedChunk]:
        for chunk, _ in life_chunks(frames(), db, robot, integrator, e0=e0, breaks=breaks,
                                    max_wheel_speed_mm_s=max_wheel_speed_mm_s, info=info,
                                    on_encoders=on_encoders if losses else None,
                                    left_out=stalled.left_out):
            if losses:
                drops.named(chunk.enc)
            across.named(chunk.enc)  # the same each pass: the first sets it
            yield chunk

    info = LifeInfo()
    x0, y0, h0, exact = place_start(lambda: placed(info), power_up=at_first)
    x0, y0, h0 = start_pose if start_pose is not None else (x0, y0, h0)
    # the offsets' pass also weighs the lossy spans (losses.loss_allowance) and keeps the
    # counts across the stalls' breaks (their allowance)
    raw = segment_offsets(lambda: placed(losses=True), (x0, y0, h0), info.segments + 1)
    seen, reprimed = whole_only(seen_all, info, NotStreamable)  # gapseen
    off_x, off_y, placements = placed_offsets(
        *raw, info.openings, lambda b: stalled.allowance_m[b] if b in stalled.allowance_m
        else across.allowance(b, seen, reprimed),
        lambda b: 0.0 if b in info.by_uptime or seen.gap_missed(b, reprimed)  # reference_path's
        else min(gap_or_fill_allowance(seen.filled(b, reprimed),  # gapfill: late frames
            *info.gap_steps[b], geometry, bits, integrator, max_wheel_speed_mm_s),
            skips.allowance_m(b, seen.skipped(b, reprimed), geometry, bits, integrator),
            received_allowance_m(received_fill(seen, b, reprimed), *info.gap_steps[b], geometry,
                                 bits, integrator, max_wheel_speed_mm_s)),  # gapreceived
        tolerance.position_m)
    offsets = (off_x, off_y)
    truth = TruthCompare((x0, y0, h0), offsets, rebase=rebase, e0=e0)
    last: list[PlacedChunk] = []
    wanted = (frozenset(info.reprimed) | frozenset(breaks.tolist())
              | frozenset(first for first, _, _ in spans)
              | frozenset(e0 + rep.r for rep in stalled.reprimes.values()))
    final = LifeInfo()

    def with_truth() -> Iterator[PlacedChunk]:
        for chunk, told in life_chunks(frames(), db, robot, integrator, e0=e0, breaks=breaks,
                                       max_wheel_speed_mm_s=max_wheel_speed_mm_s, info=final,
                                       times_of=wanted, left_out=stalled.left_out):
            truth.feed(chunk, told)
            if len(chunk.enc):
                last[:] = [chunk]
            yield chunk

    vs_ref = reference_errors(with_truth, (x0, y0, h0), offsets, drops.allowance)
    if stallrestart.word_denies(info.by_uptime, final.times_s, breaks, seen_all.resets):
        raise NotStreamable(stallrestart.STREAM)  # the stalls' windows: judged whole
    vs_truth = truth.summary()
    vs_truth["distance_travelled_m"] = float(last[0].rel_distance_m[-1])
    twist = first.twist.finish()
    distance = stream_distance(frames, db, robot, integrator, e0, DistanceJudge(
        robot, max_wheel_speed_mm_s, power_up and start_pose is None,
        [b for b in breaks.tolist() if b > e0],
        [(a, z) for a, z, _ in spans],
        skipped=first.losses.ok_spans(power_up and start_pose is None),
        took_none=took_none(seen, reprimed)))
    after_span = drops.allowance(np.array([last + 1 for _, last, _ in spans], dtype=np.int64))
    left_out = stream_first(frames, db, robot, integrator, bits,  # stallfirst
                            (tolerance.position_m, tolerance.heading_rad))
    passed = bool(
        vs_ref["max_position_error_beyond_allowance_m"] <= tolerance.position_m
        and vs_ref["max_heading_error_rad"] <= tolerance.heading_rad
        and twist["passed"] and distance["passed"] and left_out.passed()
    )
    covered_s = facts.covered_s()
    counts = first.e2e.counts
    report = {
        "robot": robot_dict(robot),
        "integrator": integrator,
        "integrator_source": source,
        "reference_start": "set pose" if start_pose else "power-up" if exact else "fitted",
        "scenario": scenario,
        "seed": seed,
        "sim_seconds": covered_s, "first_frame_s": facts.first_frame_s,
        "wall_seconds": wall_seconds,
        "realtime_factor": realtime(covered_s, wall_seconds),
        "frames": facts.frame_counts,
        "samples": {
            "onboard": first.kept,
            "truth": first.truths,
            "truth_compared": truth.compared,
            "unmatched_poses": first.poses.unmatched,
            "encoder_frames": first.encoders, "unmatched_sent": first.poses.unmatched_sent(),
            "reference_restarts": info.segments, "unseen_restarts": 0,  # else: whole_only
            "implausible_encoder_frames": info.refused, **left_out.counts(),
        },
        "reference_breaks": placements.as_dict(),
        "events": [
            {"kind": "counter_restart", "t_s": final.times_s[e], "encoder_frame": int(e),
             "detail": restart_detail(e in info.by_uptime, ambiguous=e in info.ambiguous)}
            for e in info.reprimed
        ] + [
            {"kind": "stall_reprime", "t_s": final.times_s[e0 + rep.r],
             "encoder_frame": e0 + rep.r, "detail": reprime_detail(rep.stall_s, rep.sure)}
            for _, rep in sorted(stalled.reprimes.items())
        ] + [
            {"kind": "firmware_stall", "t_s": final.times_s[e], "encoder_frame": int(e),
             "detail": STALL_DETAIL}
            for e in breaks.tolist() if e > int(first.head.enc[0])
        ] + [
            {"kind": "encoder_frames_lost_on_board", "t_s": final.times_s[begin],
             "encoder_frame": int(begin),
             "detail": f"the firmware reports {n} encoder frames lost up to encoder frame "
                       f"{end} that the log holds (its mailbox overflowed): it took their "
                       "steps as one, so its position may leave the fine reference by up to "
                       f"{allowed * 1e3:.4f} mm from here (loss_allowance_m)"}
            for (begin, end, n), allowed in zip(spans, after_span.tolist(), strict=True)
        ],
        **first.facts.firmware_fields(),
        "reboots": [],
        "onboard_vs_reference": vs_ref,
        "onboard_vs_truth": vs_truth,
        "onboard_twist_vs_reference": twist, "stall_first_pose": left_out.as_dict(),
        "onboard_distance_vs_reference": distance,
        "final_onboard_pose": {
            "x_m": float(first.tail.x_m[-1]),
            "y_m": float(first.tail.y_m[-1]),
            **heading_fields(float(first.tail.heading_rad[-1])),
        },
        "e2e": {name: c for name, c in counts.items() if name != UNKNOWN},
        "unknown_frames": counts[UNKNOWN],
        "tolerance": {"position_m": tolerance.position_m, "heading_rad": tolerance.heading_rad},
        "passed": passed,
    }
    if rebase:  # a life after a reboot: the truth compared in its frame
        report["truth_origin"] = truth.origin
    return report, first.t_first_s


def _said_already(_message: str) -> None:
    """The whole log's read after the stream's: its warnings were said (``iter_log``'s)."""
