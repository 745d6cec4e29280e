"""The host's check of a drive: on-board pose vs float64 reference vs ground truth, from frames.

Everything comes from the bus (``FrameArrays``, live or from a log), decoded with the DBC:

1. **E2E** (``host.e2e.check_frames``): only accepted frames count.
2. **Encoder sequence**: the accepted WHEEL_ENCODERS frames, each with its place in the sender's
   sequence (the COUNTER unwrapped: counter differences mod 16, widened by 16 when the timestamps
   say that many periods passed).
3. **Alignment, exact** (never by nearest time): a pose frame's ENC_COUNTER names the encoder frame
   the firmware had integrated last. It is resolved against the latest accepted encoder frame
   before the pose frame, L: the named frame is ``seq(L) + wrap_i4(ENC_COUNTER - COUNTER(L))``
   (-8..+7 frames from L; normally 0). When that frame is accepted in the log before the pose
   frame, the pose belongs to it; when it is not (the log missed a frame the firmware had, or
   it comes later: the firmware cannot have integrated it), the pose is left out rather than
   paired with a frame 16 counts away. A pose naming the same ENC_COUNTER as the one its sender
   sent just before (COUNTER + 1, less than ``SILENCE_CYCLES`` cycles earlier) names the same
   frame: E2E refuses a repeated counter, so the firmware cannot have moved on by exactly 16
   frames in one send period (a firmware held on one frame while the bus went on, e.g. its
   E2E window shut after a late frame and a lost one, keeps naming it). ODOM_POSE_X and
   ODOM_POSE_Y naming the same encoder frame make one on-board sample (the first of each, if
   the pose was sent again). SIM_TRUTH's three parts (X, Y, HEADING) naming one encoder frame
   make one truth sample (named by the simulator, whenever its encoder frame reaches the bus).
4. **Reference**: ``host.reference.integrate`` over the count deltas of the accepted encoder frames
   (mod 2^min(counter_bits, 24), what the wire carries), started at the first on-board sample.
   The start pose is exact when the log starts at power-up (``host.judge.powerup``): the firmware
   starts at pose 0 on the first encoder frame it accepts (by contract; a set-pose is the only
   other start), so a log whose first ODOM_STATUS summary says UPTIME 0 and whose first
   ODOM_STATUS page of encoder E2E counts says the firmware had accepted exactly the log's encoder
   frames (it primed on the log's first: a recorder started late is not a power-up) starts the
   reference at exactly (0, 0, 0) on its first encoder frame, whatever its first on-board sample
   reads: a firmware that powers up off (0, 0, 0), by one LSB or by 0.1 m, FAILs (a page that
   counts the log's first k frames fewer, all before the firmware's first cycle, starts it at
   (0, 0, 0) on frame k: ``powerup.primed_after``, ``primedon``). The exact start
   is not checked against the samples: a wrong firmware drifting from the start must be judged
   from it, not from a start fitted to its drift. Without that page (other firmwares need not send
   it) the first sample must also name the first accepted encoder frame and read exactly 0 (X, Y,
   HEADING, TURNS); then a recorder started in the firmware's first second after the robot moved
   less than half an LSB would be taken for a power-up. Any other log (mid-drive) has its start
   fitted to below its resolution: the on-board values are rounded to 0.1 mm and 2 pi/65536 rad,
   so the start heading is the middle of the overlap of the heading intervals of *every* sample of
   the log (less the reference's own increments): N samples at varied headings pin it to about
   2^-16 turn / N. The heading error rotates the whole reference about the start, so on a drive
   with little heading variation (a long straight) the rotation is then taken from the positions
   of all samples (least squares, each segment between gaps of the encoder sequence with an offset
   of its own, see step 4's gaps below), never leaving the heading overlap: a rotation the heading
   samples allow is one the log cannot tell from a different start. The start position is the
   middle of the overlap of the first samples' position intervals. Without that, a start heading
   off by its residual (7e-8 rad) grows as residual x distance, enough to fail a correct firmware
   after 600 m. The reference takes the steps the firmware is specified to take (firmware/ecu.py):
   a frame beyond the plausibility bound (the profile's ``max_wheel_speed_m_s`` over its periods,
   widened by the bus time as the firmware widens them by its clock's: ``step_periods``) is
   refused, ``RESYNC_FRAMES`` refused frames consistent among themselves are a counter restart,
   re-primed on the first of them (a ``counter_restart`` event; the motion across it is lost on
   board and in the reference alike).
   After the firmware was silent for ``SILENCE_CYCLES`` cycles (a stalled MCU) its first pose,
   naming a backlog frame ENC_COUNTER cannot resolve, is left out, and the position is placed
   again (a ``firmware_stall`` event): the firmware took the frames it missed as one step (or
   several). Likewise when two consecutive samples name frames ``SILENCE_CYCLES`` or more apart
   while the log holds the frames between (the firmware integrated none of them, then one step).
   That placement is bounded (``host.judge.breaks``): it may move the position by no more than
   the worst merge error of the frames the firmware may have missed there, summed over the
   stalls since the last free placement, plus the position tolerance; a larger offset is not
   absorbed, the samples after the stall show the rest. A gap of the log's encoder sequence
   (frames the logger missed, which the firmware may have integrated one by one, each within
   its plausibility bound) places it too, within the worst merge error of any such split of
   the merged step (``host.judge.gapbound``), summed with the stalls' since the start. Where
   the firmware's own ODOM_STATUS E2E pages prove it accepted exactly the log's encoder frames
   (every one the log holds, none it lacks: ``host.judge.gapseen``), it took the reference's
   steps there: a gap or a stall there is placed with no allowance but the tolerance.
   ``reference_breaks`` in the report counts both and gives the largest offset a stall's and
   a gap's placement asked for, with its allowance, and the most any went beyond it.
5. **Errors**: position errors are Euclidean distances (m), heading errors wrapped to [-pi, pi).
   On-board vs reference at every on-board sample; on-board vs truth at every truth sample that
   has an on-board sample of the same encoder frame. Where the firmware reports encoder frames
   lost that the log holds (ODOM_STATUS ENC_E2E_LOST grew by more than the log's own gaps: its
   mailbox overflowed), it took two steps as one there: the position may leave the fine
   reference by the sum of the largest such merge errors (``losses.loss_allowance``, reported
   as ``loss_allowance_m`` and an ``encoder_frames_lost_on_board`` event per span), which the
   verdict allows on top of the tolerance; the heading stays exact (a function of the counts).
   Likewise an encoder frame with a twin (``samples.twinned_encoder_frames``): the firmware may
   have integrated the twin, a detour the reference did not take; each twin's worst detour
   (``host.judge.twins``) is allowed from its frame on, summed (``reference_breaks``' ``twins``
   and ``twin_allowance_m``).

6. **Reboots** (``host.judge.reboots``): a firmware restart (UPTIME going back, or INIT after
   running: ``host.judge.sources.SourceWatch`` live) cuts the log into lives, each judged from its
   power-up pose (0 at the frame it primed on; ``powerupjudged``), E2E afresh; a ``reboot`` event.

The code: this module runs the steps and writes the report; ``host.judge.samples`` steps 1-3,
``reference_path`` 4, ``compare`` 5 (and the twist and the plot series), ``reboots`` 6.

The on-board pose is the decoded signals: X, Y * 1e-4 m, HEADING * 2 pi/65536 rad
(``TURNS * 2 pi + HEADING`` unwrapped). An applied ODOM_SET_POSE cuts the log into a new life
whose reference starts at the pose set (``host.judge.setposes``), an applied ODOM_CONFIG one judged
with the robot it applied (``host.judge.configs``); ``firmware_events`` latches every
STATE change and ERROR_MASK bit set in the ODOM_STATUS summaries (``host.judge.statuslatch``).
"""

from __future__ import annotations

__all__ = ["HEADING_LSB_RAD", "POSITION_LSB_M", "REQUIRED", "Analysis", "AnalysisError",
           "Tolerance", "analyze"]

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from odocan.host.io.logs import FrameArrays
from odocan.host.judge import acrosscut, aheadcheck, cutreprime, gapskips, reportfacts
from odocan.host.judge.compare import (
    check_twist,
    error_summary,
    plot_series,
    pose_errors,
    rebased_at_start,
    versus_truth,
)
from odocan.host.judge.configs import config_cuts, cut_configs, first_integrator, in_force
from odocan.host.judge.distance import DistanceJudge, check_distance, twin_paths
from odocan.host.judge.e2estepbound import bounded
from odocan.host.judge.evidencechoice import chosen_seen
from odocan.host.judge.finalstate import firmware_fields, latched_per_firmware
from odocan.host.judge.gapseen import Seen, seen_in_log
from odocan.host.judge.holepages import page_numbered
from odocan.host.judge.judgedfloor import floored
from odocan.host.judge.keptmark import mark_kept
from odocan.host.judge.lapfirst import lap_named
from odocan.host.judge.lonehalves import judge_lone, unmatched_sent
from odocan.host.judge.losses import (
    firmware_losses,
    firmware_ok_spans,
    life_placements,
    loss_allowance,
)
from odocan.host.judge.posestreams import one_source_cut
from odocan.host.judge.powerup import saw_only_the_log, starts_at_power_up
from odocan.host.judge.powerupjudged import fold_power_up, power_up_errors
from odocan.host.judge.primedon import each_prime
from odocan.host.judge.reboots import Life, mark_two_sources, merge, split_lives
from odocan.host.judge.reference import PROFILE_SPEED, Geometry, SpeedBound
from odocan.host.judge.reference_path import (
    Reference,
    build_reference,
    firmware_steps,
    restart_detail,
)
from odocan.host.judge.refusednames import refused_frames
from odocan.host.judge.reportfacts import covered_s, frame_counts, realtime, robot_dict
from odocan.host.judge.reprimecount import power_up_lost
from odocan.host.judge.resent import worst_sent
from odocan.host.judge.samples import (
    HEADING_LSB_RAD,
    POSITION_LSB_M,
    REQUIRED,
    WIRE_COUNTER_BITS,
    AnalysisError,
    Encoders,
    encoder_frames,
    onboard_samples,
    pick_integrator,
    require_messages,
    truth_samples,
    wrap_pi,
)
from odocan.host.judge.setposekept import Kept, check_cut
from odocan.host.judge.setposes import cut_lives, set_pose_cuts
from odocan.host.judge.silentboot import primed_in_silence
from odocan.host.judge.silentlives import SilentLife, add_silent, silent_life
from odocan.host.judge.stallfirst import STALL_DETAIL, judge_left_out
from odocan.host.judge.stallpowerup import log_power_up
from odocan.host.judge.stallreprime import reprime_events
from odocan.host.judge.stalls import after_stalls, first_placement, primed_first, signs_of_life
from odocan.host.judge.twins import twin_allowance_of
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import UNKNOWN, check_frames
from odocan.host.protocol.pose import heading_fields
from odocan.sim.robot import RobotProfile

if TYPE_CHECKING:  # a cantools Database or a plan of it (host.protocol.dbcplan)
    from odocan.host.protocol.dbcplan import DatabaseSpec


@dataclass(frozen=True)
class Tolerance:
    """Pass limits of on-board vs reference (position as a distance, heading wrapped)."""
    position_m: float = POSITION_LSB_M  # one LSB of the pose position signals
    heading_rad: float = HEADING_LSB_RAD  # one LSB of HEADING


@dataclass
class Analysis:
    """The result: the JSON report, the series for plots and exports, and the verdict.

    ``series``: per on-board sample ``timestamp_s`` (its encoder frame's), ``onboard_*``,
    ``reference_*`` (x_m, y_m, heading_rad), ``distance_m``, ``position_error_m``,
    ``heading_error_rad`` (on-board minus reference); per compared truth sample
    ``truth_timestamp_s``, ``truth_*`` and ``truth_position_error_m``/``truth_heading_error_rad``
    (on-board minus truth).
    """

    report: dict[str, Any]
    series: dict[str, np.ndarray] = field(default_factory=dict)
    passed: bool = False


@bounded  # the robot's step bound for the E2E checks' skip proofs (e2e_bound)
@aheadcheck.checked  # a pose naming an encoder frame not yet sent: FAIL
@floored  # fewer than half the poses judged: no PASS
def analyze(
    frames: FrameArrays,
    robot: RobotProfile,
    integrator: str | None = None,
    *,
    tolerance: Tolerance = Tolerance(),
    db: DatabaseSpec | None = None,
    scenario: str | None = None,
    seed: int | None = None,
    wall_seconds: float | None = None,
    max_wheel_speed_mm_s: SpeedBound = PROFILE_SPEED,
) -> Analysis:
    """Check the on-board odometry in ``frames`` (see the module docstring).

    ``max_wheel_speed_mm_s``: the firmware's plausibility bound (its build-time maximum rim
    speed): the reference refuses and re-primes where the firmware does; None: every step is
    integrated (for synthesized drives faster than any ECU build allows).

    ``integrator`` None: the one ODOM_STATUS reports. ``scenario``, ``seed``, ``wall_seconds``
    (the wall-clock time the run took) only go into the report. Raises ``AnalysisError`` when the
    DBC does not match the frames or there is nothing to compare.
    """
    db = db if db is not None else default_plan()
    decoder = BulkDecoder(db)
    require_messages(decoder)
    conflict = one_source_cut(frames, decoder, db)
    if conflict is not None:  # judged up to where the second source came, then a FAIL
        cut, t_s, detail = conflict
        one = analyze(frames.select(np.arange(cut)), robot, integrator, tolerance=tolerance,
                      db=db, scenario=scenario, seed=seed, wall_seconds=wall_seconds,
                      max_wheel_speed_mm_s=max_wheel_speed_mm_s)
        mark_two_sources(one.report, t_s, len(frames) - cut, detail)
        return Analysis(report=one.report, series=one.series, passed=False)
    firmware_lives = split_lives(frames, decoder)
    lives = cut_configs(cut_lives(firmware_lives, set_pose_cuts(frames, decoder)),
                        config_cuts(frames, decoder, robot.counter_bits))
    if len(lives) == 1:
        return _analyze_life(frames, robot, integrator, tolerance=tolerance, db=db,
                             decoder=decoder, scenario=scenario, seed=seed,
                             wall_seconds=wall_seconds, max_wheel_speed_mm_s=max_wheel_speed_mm_s)
    _, accepted = check_frames(frames, db)
    integrator, source = pick_integrator(frames, accepted, decoder, integrator)
    across = acrosscut.cut_evidence(frames, db, firmware_lives, lives)  # a stall across a cut
    done: list[tuple[Life, Analysis, float]] = []
    failure: AnalysisError | None = None
    silent: list[Life] = []
    unjudged: list[SilentLife] = []  # their frames counted, their stretch said (silentlives)
    kept: dict[int, Kept] = {}  # per set-pose's life: what it kept (setposekept)
    for k, (life, (life_robot, life_integrator, bound)) in enumerate(zip(
            lives, in_force(lives, robot, first_integrator(frames, lives, decoder, integrator,
                                                            source), max_wheel_speed_mm_s),
            strict=True)):
        part = frames.select(life.index)
        try:
            result = _analyze_life(part, life_robot, life_integrator, tolerance=tolerance, db=db,
                                   decoder=BulkDecoder(db), boot=life.boot,
                                   rebase=life.t_s is not None and life.config is None,
                                   max_wheel_speed_mm_s=bound,
                                   start_pose=life.set_pose and life.set_pose.start_pose(),
                                   later=acrosscut.later_word(across, lives, k, frames.timestamp_s),
                                   backlog=acrosscut.backlog_of(across, lives, k),
                                   silent=life.silent)
        except AnalysisError as exc:  # a life without on-board samples: reported, not compared
            failure = failure or exc
            silent.append(life)
            if said := silent_life(frames, life, life_robot, life_integrator, db, str(exc)):
                unjudged.append(said)
            continue
        if life.set_pose is not None:
            kept[len(done)] = check_cut(lambda lo, hi: frames.select(np.arange(lo, hi)), (
                int(lives[k - 1].index[0]), lives[k - 1].boot), int(life.index[-1]) + 1,
                life.set_pose, life_robot, life_integrator, db, bound)
        done.append((life, result, float(part.timestamp_s[0])))
    if not done:
        assert failure is not None
        raise failure
    report, series = merge([d[1].report for d in done], [d[1].series for d in done],
                           [d[0] for d in done], [d[2] for d in done], silent=silent)
    add_silent(report, unjudged)
    if len(lives) != len(firmware_lives):  # a set-pose is no reboot: one latch per firmware
        report.update(latched_per_firmware(frames, firmware_lives, db))
    seconds = covered_s(frames, db)
    report.update(
        integrator_source=source, scenario=scenario, seed=seed, sim_seconds=seconds,
        first_frame_s=reportfacts.first_frame_s(frames), wall_seconds=wall_seconds,
        realtime_factor=realtime(seconds, wall_seconds), frames=frame_counts(frames, decoder),
    )
    vs_ref = report["onboard_vs_reference"]
    report["passed"] = bool(
        vs_ref["max_position_error_m"] is not None
        and all(d[1].passed for d in done)  # each life within its tolerance and allowance
        and vs_ref["max_heading_error_rad"] <= tolerance.heading_rad
        and report["onboard_twist_vs_reference"]["passed"]
        and report["onboard_distance_vs_reference"]["passed"]
    )
    mark_kept(report, kept)  # a set-pose that changed a field it kept: FAIL
    return Analysis(report=report, series=series, passed=report["passed"])


@each_prime  # a stall at power-up's unproven start: judged from each frame it may have primed on
def _analyze_life(
    frames: FrameArrays,
    robot: RobotProfile,
    integrator: str | None,
    *,
    tolerance: Tolerance,
    db: DatabaseSpec,
    decoder: BulkDecoder,
    boot: bool = False,
    rebase: bool = False,
    scenario: str | None = None,
    seed: int | None = None,
    wall_seconds: float | None = None,
    max_wheel_speed_mm_s: SpeedBound = PROFILE_SPEED,
    start_pose: tuple[float, float, float] | None = None,
    later: acrosscut.Word | None = None,
    backlog: cutreprime.Backlog | None = None, silent: bool = False,
) -> Analysis:
    """``analyze`` of one firmware life (``host.judge.reboots``); ``boot``: the frames start at
    a reboot, the firmware's pose 0 at their first encoder frame; ``rebase``: the frames are a
    life after a reboot or a set-pose, the truth is compared in its frame
    (``compare.life_origin``); ``start_pose``: a set-pose's, exact at the first encoder frame
    (``host.judge.setposes``); ``later``: the same firmware's summaries after a cut, ``backlog``:
    its first sample names a backlog frame (``acrosscut``); ``silent``: ``silentboot``'s life."""
    e2e, accepted = check_frames(frames, db)
    integrator, source = pick_integrator(frames, accepted, decoder, integrator)
    enc = page_numbered(frames, decoder, encoder_frames(frames, accepted, decoder))
    enc, halves = lap_named(frames, accepted, decoder, enc, (robot, integrator, start_pose))
    onboard, unmatched, sent_s = onboard_samples(frames, accepted, decoder, enc, halves)
    onboard, sent_s = acrosscut.without_first(onboard, sent_s) if backlog else (onboard, sent_s)
    pose_sent_s, alive_s = signs_of_life(frames, accepted, decoder)  # poses: CRC right too
    onboard, stalls = after_stalls(onboard, sent_s, enc, pose_sent_s, alive_s, halves)
    left_out = judge_left_out(halves, onboard, enc, Geometry.of(robot), integrator, min(
        robot.counter_bits, WIRE_COUNTER_BITS), (tolerance.position_m, tolerance.heading_rad),
        pose_sent_s, stalls, max_wheel_speed_mm_s)
    first = first_placement(sent_s, enc, alive_s, pose_sent_s, onboard)  # no loss span's
    truth = truth_samples(frames, accepted, decoder, enc)
    unproven: list[dict[str, Any]] = []  # its first count pages lost: said (stallpowerup)
    if silent:  # rebooted unheard: (0, 0, 0) on each frame it may have primed on (silentboot)
        power_up, unproven = False, ([] if start_pose else primed_in_silence(
            frames, decoder, enc, onboard, float(np.min(sent_s)), (robot, integrator)))
    elif boot:  # (a stalled MCU's first page misses the frames its FIFO overran: primed_first)
        power_up = saw_only_the_log(frames, accepted, decoder) or primed_first(
            float(np.min(sent_s, initial=np.inf)), enc, alive_s, pose_sent_s)
    elif rebase or start_pose:  # not the log's first life: its count pages only
        power_up = starts_at_power_up(frames, accepted, decoder, onboard)
    else:  # the log's first life: a stall at power-up vetoes the page's tick bound
        power_up, unproven = log_power_up(frames, accepted, decoder, onboard, enc,
                                          (sent_s, alive_s), (robot, integrator))
    losses = firmware_losses(frames, accepted, decoder, enc, power_up and start_pose is None)
    ref_all = build_reference(enc, onboard, robot, integrator, power_up=power_up, cut=backlog,
                         max_wheel_speed_mm_s=max_wheel_speed_mm_s, breaks=stalls,
                         lossy=[first for first, _, _ in losses], late=halves.refused,
                         slack_m=tolerance.position_m, start_pose=start_pose,
                         reprime_lost=power_up_lost(frames, accepted, decoder, enc, stalls),
                         seen=(seen := chosen_seen(  # an evidenceless ambiguous gap
                             enc, onboard, Geometry.of(robot), integrator,
                             e0=0 if power_up or start_pose is not None else int(onboard.enc[0]),
                             bits=min(robot.counter_bits, WIRE_COUNTER_BITS),
                             max_wheel_speed_mm_s=max_wheel_speed_mm_s,
                             seen=acrosscut.heard_later(seen_in_log(
                                 frames, decoder, enc, power_up=power_up), later))))
    onboard = worst_sent(onboard, halves, ref_all, tolerance.position_m, tolerance.heading_rad)
    ref = ref_all.at(onboard.enc)
    truth_origin = None
    if rebase:  # a new firmware life: its own origin, the truth re-based there
        truth, truth_origin = rebased_at_start(truth, ref_all)
    pos_err, head_err = pose_errors(onboard, ref)
    vs_ref = error_summary(pos_err, head_err)
    vs_truth, truth_series = versus_truth(onboard, truth, ref_all)
    vs_truth["distance_travelled_m"] = float(ref.distance_m[-1])
    twist = check_twist(frames, accepted, decoder, enc, robot)
    placed = life_placements(first, stalls, onboard.enc, ref_all.start, ref_all.stall_reprimes)
    allowance = loss_allowance(enc, robot, integrator, losses, onboard.enc, onboard.enc, placed)
    vs_ref["loss_allowance_m"] = float(np.max(allowance, initial=0.0))
    after_span = loss_allowance(enc, robot, integrator, losses,
                                np.array([last + 1 for _, last, _ in losses], dtype=np.int64),
                                onboard.enc, placed)
    twin_allowed = twin_allowance_of(enc, robot, integrator, ref_all, onboard.enc)
    distance = _distance(frames, accepted, decoder, enc, robot, ref_all,
                         DistanceJudge(robot, max_wheel_speed_mm_s, power_up and not start_pose,
                                       [b for b in stalls.tolist() if b > ref_all.start],
                                       [(a, z) for a, z, _ in losses],
                                       twin_paths(enc, robot, ref_all.start),
                                       firmware_ok_spans(frames, accepted, decoder, enc,
                                                         power_up and start_pose is None)),
                         seen, alive_s)
    vs_ref["max_position_error_beyond_allowance_m"] = float(
        np.max(pos_err - allowance - twin_allowed))
    (lone := judge_lone(halves, onboard, enc, ref_all, stalls, pose_sent_s, (
        robot, integrator, losses, placed), left_out.lone_rows, seen)).fold(vs_ref)  # lonehalves
    fold_power_up(vs_ref, power_up_errors(frames, decoder, enc, ref_all, onboard.enc, start_pose))
    passed = bool(
        vs_ref["max_position_error_beyond_allowance_m"] <= tolerance.position_m
        and vs_ref["max_heading_error_rad"] <= tolerance.heading_rad
        and twist["passed"]
        and distance["passed"] and left_out.passed()
    )
    report = {
        "robot": robot_dict(robot),
        "integrator": integrator, "integrator_source": source,
        "reference_start": "set pose" if start_pose else (
            "power-up" if ref_all.exact_start else "fitted"),
        "scenario": scenario, "seed": seed,
        "sim_seconds": covered_s(frames, db), "first_frame_s": reportfacts.first_frame_s(frames),
        "wall_seconds": wall_seconds,
        "realtime_factor": realtime(covered_s(frames, db), wall_seconds),
        "frames": frame_counts(frames, decoder),
        "samples": {
            "onboard": len(onboard.enc),
            "truth": len(truth.enc), "truth_compared": len(truth_series["truth_x_m"]),
            "unmatched_poses": unmatched,
            "encoder_frames": len(enc.index), "unmatched_sent": unmatched_sent(halves),
            "reference_restarts": ref_all.restarts,
            "unseen_restarts": len(ref_all.unseen_restarts),  # new starts: unseenrestart
            "implausible_encoder_frames": ref_all.implausible_frames, **left_out.counts(),
            **lone.counts(),
        },
        "reference_breaks": ref_all.placements.as_dict(),
        "events": [
            {"kind": "counter_restart", "t_s": float(frames.timestamp_s[enc.index[e]]),
             "encoder_frame": int(e),
             "detail": restart_detail(e in ref_all.ctrl_restarts, e in ref_all.unseen_restarts,
                                      ambiguous=e in ref_all.ambiguous)}
            for e in ref_all.counter_restarts
        ] + reprime_events(frames.timestamp_s, enc, ref_all.start, ref_all.stall_reprimes) + \
            unproven + [
            {"kind": "firmware_stall", "t_s": float(frames.timestamp_s[enc.index[e]]),
             "encoder_frame": int(e),
             "detail": STALL_DETAIL}
            for e in stalls.tolist() if e > int(onboard.enc[0])
        ] + [
            {"kind": "encoder_frames_lost_on_board",
             "t_s": float(frames.timestamp_s[enc.index[first]]), "encoder_frame": int(first),
             "detail": f"the firmware reports {n} encoder frames lost up to encoder frame "
                       f"{last} that the log holds (its mailbox overflowed): it took their "
                       "steps as one, so its position may leave the fine reference by up to "
                       f"{allowed * 1e3:.4f} mm from here (loss_allowance_m)"}
            for (first, last, n), allowed in zip(losses, after_span.tolist(), strict=True)
        ],
        **firmware_fields(frames, accepted, decoder),
        "reboots": [],
        "onboard_vs_reference": vs_ref, "onboard_vs_truth": vs_truth,
        "onboard_twist_vs_reference": twist, "stall_first_pose": left_out.as_dict(),
        "onboard_distance_vs_reference": distance,
        "final_onboard_pose": {  # heading_rad in (-pi, pi], heading_unwrapped_rad cumulative
            "x_m": float(onboard.x_m[-1]),
            "y_m": float(onboard.y_m[-1]),
            **heading_fields(float(onboard.heading_rad[-1])),
        },
        "e2e": {name: c for name, c in e2e.items() if name != UNKNOWN},
        "unknown_frames": e2e[UNKNOWN],
        "tolerance": {"position_m": tolerance.position_m, "heading_rad": tolerance.heading_rad},
        "passed": passed,
    }
    if rebase:
        report["truth_origin"] = truth_origin
    truth_enc = truth_series.pop("truth_enc")
    series = {
        "timestamp_s": frames.timestamp_s[enc.index[onboard.enc]],  # of the encoder frame
        "onboard_x_m": onboard.x_m,
        "onboard_y_m": onboard.y_m,
        "onboard_heading_rad": wrap_pi(onboard.heading_rad),  # (-pi, pi]
        "onboard_heading_unwrapped_rad": onboard.heading_rad,
        "reference_x_m": ref.x_m,
        "reference_y_m": ref.y_m,
        "reference_heading_rad": wrap_pi(ref.heading_rad),
        "reference_heading_unwrapped_rad": ref.heading_rad,
        "distance_m": ref.distance_m,
        "position_error_m": pos_err,
        "heading_error_rad": head_err,
        **truth_series,
        "truth_timestamp_s": frames.timestamp_s[enc.index[truth_enc]],
    }
    series.update(plot_series(frames, enc, onboard, truth, ref_all))
    return Analysis(report=report, series=series, passed=passed)


def _distance(frames: FrameArrays, accepted: np.ndarray, decoder: BulkDecoder, enc: Encoders,
              robot: RobotProfile, ref: Reference, judge: DistanceJudge, seen: Seen,
              alive_s: np.ndarray) -> dict[str, Any]:
    """``distance.check_distance`` over the firmware's steps from the reference's start (``seen``:
    holetaken, nearthreshold, gapskips; cutreprime; stallrestart's windows; refusednames)."""
    judge.took_none, e0 = gapskips.took_none(seen, frozenset(ref.counter_restarts)), ref.start
    steps = firmware_steps(enc, e0, Geometry.of(robot), min(robot.counter_bits, WIRE_COUNTER_BITS),
                           judge.max_wheel_speed_mm_s, through=seen.through, resets=seen.resets,
                           stalled=ref.stalled)
    cutreprime.cut_left_out(steps.d_left, steps.d_right, ref.stall_reprimes)
    return check_distance(frames, accepted, decoder, enc, (steps.d_left, steps.d_right,
                          refused_frames(steps, len(enc.seq) - e0)), e0, judge, alive_s)
