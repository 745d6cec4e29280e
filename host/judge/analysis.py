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
   The start pose is exact when the log starts at power-up: the firmware starts at pose 0 on the
   first encoder frame it accepts, so a log whose first on-board sample names its first accepted
   encoder frame, reads exactly 0 (X, Y, HEADING, TURNS) and whose first ODOM_STATUS summary says
   UPTIME 0 starts the reference at exactly (0, 0, 0) -- provided, when the log has one, that the
   first ODOM_STATUS page of encoder E2E counts says the firmware had accepted exactly the log's
   encoder frames (it primed on the log's first: a recorder started late is not a power-up). The
   exact start is not checked against the samples: a wrong firmware drifting from the start must
   be judged from it, not from a start fitted to its drift. Without that page, a recorder
   started in the firmware's first second after the robot moved less than half an LSB would be
   taken for a power-up. Any other log (mid-drive) has its start fitted to below its resolution: the
   on-board values are rounded to 0.1 mm and 2 pi/65536 rad, so the start heading is the middle
   of the overlap of the heading intervals of *every* sample of the log (less the reference's
   own increments): N samples at varied headings
   pin it to about 2^-16 turn / N. The heading error rotates the whole reference about the start,
   so on a drive with little heading variation (a long straight) the rotation is then taken from
   the positions of all samples (least squares, each segment between gaps of the encoder
   sequence with an offset of its own, see step 4's gaps below), never leaving the heading overlap:
   a rotation the heading samples allow is one the log cannot tell from a different start. The
   start position is the middle of the overlap of the first samples' position intervals.
   Without that, a start heading off by its residual (7e-8 rad) grows as residual x distance,
   enough to fail a correct firmware after 600 m.
   The reference takes the steps the firmware is specified to take (firmware/ecu.py): a frame
   beyond the plausibility bound (``MAX_WHEEL_SPEED_MM_S``) is refused, ``RESYNC_FRAMES`` refused
   frames consistent among themselves are a counter restart, re-primed on the first of them (a
   ``counter_restart`` event; the motion across it is lost on board and in the reference alike).
   After the firmware was silent for ``SILENCE_CYCLES`` cycles (a stalled MCU) its first pose,
   naming a backlog frame ENC_COUNTER cannot resolve, is left out, and the position restarts like
   after a gap (a ``firmware_stall`` event): the firmware took the frames it missed as one step.
   Likewise when two consecutive samples name frames ``SILENCE_CYCLES`` or more apart while the
   log holds the frames between (the firmware integrated none of them, then one step).
5. **Errors**: position errors are Euclidean distances (m), heading errors wrapped to [-pi, pi).
   On-board vs reference at every on-board sample; on-board vs truth at every truth sample that
   has an on-board sample of the same encoder frame.

The on-board pose is the decoded signals: X, Y * 1e-4 m, HEADING * 2 pi/65536 rad
(``TURNS * 2 pi + HEADING`` unwrapped). ODOM_SET_POSE jumps are not followed (the reference would
have to restart there).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import cantools
import numpy as np
import numpy.typing as npt

from odocan.firmware.ecu import ENCODER_PERIOD_US, MAX_WHEEL_SPEED_MM_S, RESYNC_FRAMES
from odocan.host.io.logs import FrameArrays
from odocan.host.judge.reference import INTEGRATORS, Geometry, integrate, wrap_delta
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e import UNKNOWN, check_frames
from odocan.host.protocol.pose import heading_fields
from odocan.sim import contract
from odocan.sim.exceptions import OdocanError
from odocan.sim.robot import RobotProfile

# One LSB of the pose signals, from the DBC's scales (the single source of truth): X, Y 0.1 mm,
# HEADING a 16-bit binary angle (2 pi / 65536 rad).
POSITION_LSB_M = float(contract.message("ODOM_POSE_X").get_signal_by_name("X").scale)
HEADING_LSB_RAD = float(contract.message("ODOM_POSE_X").get_signal_by_name("HEADING").scale)
WIRE_COUNTER_BITS = 24  # WHEEL_ENCODERS carries the low 24 bits of each counter
SILENCE_CYCLES = 8  # pose frames this many encoder cycles apart: the firmware was stalled
START_FIT_SAMPLES = 256  # on-board samples used to place the reference start (5 s at 50 Hz)
ENC_E2E_PAGE = 2  # ODOM_STATUS page with the firmware's WHEEL_ENCODERS E2E counts
REQUIRED = ("WHEEL_ENCODERS", "ODOM_POSE_X", "ODOM_POSE_Y")

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


class AnalysisError(OdocanError):
    """The frames cannot be analysed: DBC and log do not match, nothing to compare, ..."""


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


@dataclass(frozen=True)
class _Encoders:
    """The accepted WHEEL_ENCODERS frames, in bus order."""

    index: IntArray  # position in the frames
    counter: IntArray  # E2E COUNTER
    seq: IntArray  # the sender's sequence number (COUNTER unwrapped), strictly increasing
    left: IntArray  # LEFT_COUNT (wire, 24 bits)
    right: IntArray
    timestamp_s: FloatArray
    cycle_s: float | None  # the DBC cycle time


@dataclass(frozen=True)
class _Poses:
    """Samples of a pose (on-board or truth), one per encoder frame, sorted by it."""

    enc: IntArray  # index into _Encoders
    x_m: FloatArray
    y_m: FloatArray
    heading_rad: FloatArray  # on-board: TURNS * 2 pi + HEADING; truth: HEADING (wrapped)
    heading_raw: IntArray  # HEADING, BAM16


def analyze(
    frames: FrameArrays,
    robot: RobotProfile,
    integrator: str | None = None,
    *,
    tolerance: Tolerance = Tolerance(),
    db: cantools.database.can.Database | None = None,
    scenario: str | None = None,
    seed: int | None = None,
    wall_seconds: float | None = None,
    max_wheel_speed_mm_s: int | None = MAX_WHEEL_SPEED_MM_S,
) -> Analysis:
    """Check the on-board odometry in ``frames`` (see the module docstring).

    ``max_wheel_speed_mm_s``: the firmware's plausibility bound (its build-time maximum rim
    speed): the reference refuses and re-primes where the firmware does; None: every step is
    integrated (for synthesized drives faster than any ECU build allows).

    ``integrator`` None: the one ODOM_STATUS reports. ``scenario``, ``seed``, ``wall_seconds``
    (the wall-clock time the run took) only go into the report. Raises ``AnalysisError`` when the
    DBC does not match the frames or there is nothing to compare.
    """
    db = db if db is not None else contract.database()
    decoder = BulkDecoder(db)
    _require_messages(decoder)
    e2e, accepted = check_frames(frames, db)
    integrator, source = _pick_integrator(frames, accepted, decoder, integrator)
    enc = _encoders(frames, accepted, decoder)
    onboard, unmatched, sent_s = _onboard_samples(frames, accepted, decoder, enc)
    onboard, stalls = _after_stalls(onboard, sent_s, enc)
    truth = _truth_samples(frames, accepted, decoder, enc)
    power_up = _starts_at_power_up(frames, accepted, decoder, onboard)
    ref_all = _reference(enc, onboard, robot, integrator, power_up=power_up,
                         max_wheel_speed_mm_s=max_wheel_speed_mm_s, breaks=stalls)
    ref = ref_all.at(onboard.enc)
    pos_err, head_err = _errors(onboard, ref)
    vs_ref = _summary(pos_err, head_err)
    vs_truth, truth_series = _versus_truth(onboard, truth, ref_all)
    vs_truth["distance_travelled_m"] = float(ref.distance_m[-1])
    twist = check_twist(frames, accepted, decoder, enc, robot)
    passed = bool(
        vs_ref["max_position_error_m"] <= tolerance.position_m
        and vs_ref["max_heading_error_rad"] <= tolerance.heading_rad
        and twist["passed"]
    )
    report = {
        "robot": _robot_dict(robot),
        "integrator": integrator,
        "integrator_source": source,
        "reference_start": "power-up" if ref_all.exact_start else "fitted",
        "scenario": scenario,
        "seed": seed,
        "sim_seconds": _covered_s(frames, db),
        "wall_seconds": wall_seconds,
        "realtime_factor": _realtime(_covered_s(frames, db), wall_seconds),
        "frames": _frame_counts(frames, decoder),
        "samples": {
            "onboard": len(onboard.enc),
            "truth": len(truth.enc),
            "truth_compared": len(truth_series["truth_x_m"]),
            "unmatched_poses": unmatched,
            "encoder_frames": len(enc.index),
            "reference_restarts": ref_all.restarts,
            "implausible_encoder_frames": ref_all.implausible_frames,
        },
        "events": [
            {"kind": "counter_restart", "t_s": float(frames.timestamp_s[enc.index[e]]),
             "encoder_frame": int(e),
             "detail": "the firmware re-primes here (COUNTER_RESET): the reference restarts "
                       "with it; the motion across the restart is unknowable"}
            for e in ref_all.counter_restarts
        ] + [
            {"kind": "firmware_stall", "t_s": float(frames.timestamp_s[enc.index[e]]),
             "encoder_frame": int(e),
             "detail": "the firmware was silent or held its pose (a stall): it took the frames it "
                       "missed as one step, so the reference's position is placed again after it"}
            for e in stalls.tolist() if e > int(onboard.enc[0])
        ],
        "onboard_vs_reference": vs_ref,
        "onboard_vs_truth": vs_truth,
        "onboard_twist_vs_reference": twist,
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
    truth_enc = truth_series.pop("truth_enc")
    series = {
        "timestamp_s": frames.timestamp_s[enc.index[onboard.enc]],  # of the encoder frame
        "onboard_x_m": onboard.x_m,
        "onboard_y_m": onboard.y_m,
        "onboard_heading_rad": _wrap_pi(onboard.heading_rad),  # (-pi, pi]
        "onboard_heading_unwrapped_rad": onboard.heading_rad,
        "reference_x_m": ref.x_m,
        "reference_y_m": ref.y_m,
        "reference_heading_rad": _wrap_pi(ref.heading_rad),
        "reference_heading_unwrapped_rad": ref.heading_rad,
        "distance_m": ref.distance_m,
        "position_error_m": pos_err,
        "heading_error_rad": head_err,
        **truth_series,
        "truth_timestamp_s": frames.timestamp_s[enc.index[truth_enc]],
    }
    series.update(plot_series(frames, enc, onboard, truth, ref_all))
    return Analysis(report=report, series=series, passed=passed)


# --- inputs ---------------------------------------------------------------------------------


def _require_messages(decoder: BulkDecoder) -> None:
    """The DBC must define the messages the analysis reads."""
    missing = []
    for name in REQUIRED:
        try:
            decoder.message(name)
        except DecodeError:
            missing.append(name)
    if missing:
        raise AnalysisError(f"the DBC does not define {', '.join(missing)}: not the odocan DBC?")


def _accepted(
    frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder, name: str
) -> dict[str, np.ndarray]:
    """The decoded frames of ``name`` that passed E2E; an error when there are none."""
    decoded = decoder.decode(frames, name)
    keep = accepted[decoded["index"]]
    if not keep.any():
        message = decoder.message(name)
        if len(keep) == 0:
            raise AnalysisError(
                f"no {name} frame (ID 0x{message.frame_id:03X}, {message.length} bytes) in the "
                "log: the DBC does not match the log"
            )
        raise AnalysisError(
            f"none of the {len(keep)} {name} frames passes its E2E check: "
            "the DBC does not match the log"
        )
    return {key: value[keep] for key, value in decoded.items()}


def _pick_integrator(
    frames: FrameArrays,
    accepted: npt.NDArray[np.bool_],
    decoder: BulkDecoder,
    integrator: str | None,
) -> tuple[str, str]:
    """The integrator given, or the last one ODOM_STATUS's summary page reports."""
    if integrator is not None:
        if integrator not in INTEGRATORS:
            raise AnalysisError(
                f"unknown integrator {integrator!r} (known: {', '.join(INTEGRATORS)})"
            )
        return integrator, "argument"
    try:
        page = decoder.decode_page(frames, "ODOM_STATUS", 0)
        signal = decoder.message("ODOM_STATUS").get_signal_by_name("INTEGRATOR")
    except (DecodeError, KeyError):
        page, signal = {}, None
    values = page["INTEGRATOR"][accepted[page["index"]]] if page else np.zeros(0)
    if signal is None or len(values) == 0:
        raise AnalysisError("no ODOM_STATUS summary in the log to tell the integrator: give it")
    choices: dict[Any, Any] = dict(signal.choices or {})
    name = str(choices.get(int(values[-1]), "")).lower()
    if name not in INTEGRATORS:
        raise AnalysisError(f"ODOM_STATUS reports an unknown integrator ({int(values[-1])})")
    return name, "ODOM_STATUS"


def _encoders(
    frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder
) -> _Encoders:
    """The accepted encoder frames and their sender sequence numbers."""
    enc = _accepted(frames, accepted, decoder, "WHEEL_ENCODERS")
    counter = enc["COUNTER"].astype(np.int64)
    step = (np.diff(counter) & 0xF).astype(np.int64)
    cycle_s = contract_cycle_s(decoder, "WHEEL_ENCODERS")
    if cycle_s is not None and len(step):
        periods = np.rint(np.diff(enc["timestamp_s"]) / cycle_s).astype(np.int64)
        step = step + 16 * np.maximum(0, np.rint((periods - step) / 16)).astype(np.int64)
    seq = np.concatenate(([0], np.cumsum(step))).astype(np.int64)
    return _Encoders(
        index=enc["index"], counter=counter, seq=seq,
        left=enc["LEFT_COUNT"].astype(np.int64), right=enc["RIGHT_COUNT"].astype(np.int64),
        timestamp_s=enc["timestamp_s"], cycle_s=cycle_s,
    )


def contract_cycle_s(decoder: BulkDecoder, name: str) -> float | None:
    """A message's cycle time in seconds (None when it has none)."""
    cycle_ms = decoder.message(name).cycle_time
    return cycle_ms / 1000.0 if cycle_ms else None


def match_encoder(
    enc: _Encoders, index: IntArray, enc_counter: IntArray, timestamp_s: FloatArray,
    own_counter: IntArray | None = None, *, causal: bool = True,
) -> IntArray:
    """For frames at ``index`` (sent at ``timestamp_s``) naming ``enc_counter``: the encoder
    frame named (index into ``enc``), -1 where it is not among the accepted encoder frames
    before the naming frame (module docstring, step 3). The latest accepted encoder frame must
    be less than 8 cycles older than the naming frame: else the frame named (-8..+7 from it)
    cannot be told from one 16 cycles away (after a gap of 16 frames, E2E refuses the next as a
    repetition). ``own_counter``: the naming frames' E2E COUNTER (one message), to carry a
    repeated ENC_COUNTER over consecutive sends (``_held``). ``causal`` False: the named frame
    may come later in the log (SIM_TRUTH: the simulator names its own sample, whenever the
    encoder frame reaches the bus)."""
    latest = np.searchsorted(enc.index, index) - 1
    result = np.full(len(index), -1, dtype=np.int64)
    has = latest >= 0
    if enc.cycle_s is not None:
        age_s = timestamp_s - enc.timestamp_s[np.maximum(latest, 0)]
        has &= age_s < 8 * enc.cycle_s
    latest = latest[has]
    offset = ((enc_counter[has] - enc.counter[latest] + 8) & 0xF) - 8
    target = enc.seq[latest] + offset
    found = np.minimum(np.searchsorted(enc.seq, target), len(enc.seq) - 1)
    before = (enc.index[found] < index[has]) | (not causal)  # not integrated before it came
    result[np.flatnonzero(has)] = np.where((enc.seq[found] == target) & before, found, -1)
    if own_counter is not None and enc.cycle_s is not None:
        result = _held(result, enc_counter, own_counter, timestamp_s, enc.cycle_s)
    return result


def _held(
    named: IntArray, enc_counter: IntArray, own_counter: IntArray, timestamp_s: FloatArray,
    cycle_s: float,
) -> IntArray:
    """``named`` with each frame that repeats the ENC_COUNTER of its sender's previous send
    (own COUNTER + 1, less than ``SILENCE_CYCLES`` cycles later) naming what that one named
    (module docstring, step 3), along runs of such repeats."""
    if len(named) < 2:
        return named
    repeat = np.concatenate(([False], (
        (np.diff(enc_counter) == 0)
        & ((np.diff(own_counter) & 0xF) == 1)
        & (np.diff(timestamp_s) < SILENCE_CYCLES * cycle_s)
    )))
    run_start = np.maximum.accumulate(np.where(repeat, 0, np.arange(len(named))))
    held: IntArray = named[run_start]
    return held


def _first_per_encoder(enc_idx: IntArray) -> tuple[IntArray, IntArray]:
    """Encoder frames named (sorted, unique) and the first position naming each."""
    named = enc_idx >= 0
    uniq, first = np.unique(enc_idx[named], return_index=True)
    return uniq, np.flatnonzero(named)[first]


def _onboard_samples(
    frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder, enc: _Encoders
) -> tuple[_Poses, int, FloatArray]:
    """On-board samples (X and Y frames of one encoder frame); the poses left unmatched; and
    when each sample's ODOM_POSE_Y was sent (s)."""
    px = _accepted(frames, accepted, decoder, "ODOM_POSE_X")
    py = _accepted(frames, accepted, decoder, "ODOM_POSE_Y")
    ex = match_encoder(enc, px["index"], px["ENC_COUNTER"], px["timestamp_s"],
                       px["COUNTER"].astype(np.int64))
    ey = match_encoder(enc, py["index"], py["ENC_COUNTER"], py["timestamp_s"],
                       py["COUNTER"].astype(np.int64))
    unmatched = int(np.count_nonzero(ex < 0) + np.count_nonzero(ey < 0))
    ux, fx = _first_per_encoder(ex)
    uy, fy = _first_per_encoder(ey)
    both, ix, iy = np.intersect1d(ux, uy, assume_unique=True, return_indices=True)
    if len(both) == 0:
        raise AnalysisError(
            "no ODOM_POSE_X/ODOM_POSE_Y pair names an encoder frame of the log: nothing to compare"
        )
    sx, sy = fx[ix], fy[iy]
    heading_raw = px["HEADING"][sx].astype(np.int64)
    turns = py["TURNS"][sy].astype(np.float64)
    poses = _Poses(
        enc=both.astype(np.int64),
        x_m=px["X"][sx] * POSITION_LSB_M,
        y_m=py["Y"][sy] * POSITION_LSB_M,
        heading_rad=turns * 2 * math.pi + heading_raw * HEADING_LSB_RAD,
        heading_raw=heading_raw,
    )
    return poses, unmatched, py["timestamp_s"][sy].astype(np.float64)


def _after_stalls(
    onboard: _Poses, sent_s: FloatArray, enc: _Encoders
) -> tuple[_Poses, IntArray]:
    """Samples sent after the firmware was silent for ``SILENCE_CYCLES`` encoder cycles or more
    while the log holds the encoder frames of that time (a stalled MCU, firmware/ecu.py
    TIME_LOST): the first names a frame from before the silence
    (its backlog), which ENC_COUNTER cannot resolve, so it is left out; and the firmware took the
    frames it missed as one step, which a fine reference cannot follow on a curve, so the
    reference's position restarts (a segment, like a gap) at the encoder frame after the last
    sample before the silence. The same restart where the firmware kept talking but held its
    pose (``_frozen``). Returns the samples kept and those encoder frames (sorted)."""
    if enc.cycle_s is None or len(sent_s) < 2:
        return onboard, np.zeros(0, dtype=np.int64)
    order = np.argsort(sent_s, kind="stable")  # samples are sorted by encoder frame, not sent
    sent = sent_s[order]
    # Silent while the encoder frames went on (a log that lacks both is a recorder's gap).
    # Half a cycle short of SILENCE_CYCLES: samples come in whole send periods, and time stamps
    # summed in float must not decide (79.999... ms is 80 ms).
    heard = np.searchsorted(enc.timestamp_s, sent[1:]) - np.searchsorted(enc.timestamp_s, sent[:-1])
    after = np.flatnonzero(
        (np.diff(sent) >= (SILENCE_CYCLES - 0.5) * enc.cycle_s) & (heard >= SILENCE_CYCLES - 1)
    ) + 1
    keep = np.ones(len(sent_s), dtype=bool)
    keep[order[after]] = False
    kept = _Poses(onboard.enc[keep], onboard.x_m[keep], onboard.y_m[keep],
                  onboard.heading_rad[keep], onboard.heading_raw[keep])
    breaks = np.unique(np.concatenate((onboard.enc[order[after - 1]] + 1, _frozen(kept, enc))))
    return kept, breaks.astype(np.int64)


def _frozen(onboard: _Poses, enc: _Encoders) -> IntArray:
    """Encoder frames after a sample whose next sample names a frame ``SILENCE_CYCLES`` or more
    periods later while the log holds the frames between: the firmware held its pose on one frame
    (it kept naming it) and then took the frames since as one step, as after a stall."""
    seq = enc.seq[onboard.enc]
    held = (np.diff(seq) >= SILENCE_CYCLES) & (np.diff(onboard.enc) >= SILENCE_CYCLES)
    frozen: IntArray = onboard.enc[:-1][held] + 1
    return frozen


def _truth_samples(
    frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder, enc: _Encoders
) -> _Poses:
    """Truth samples (X, Y and HEADING parts naming one encoder frame); empty without SIM_TRUTH."""
    try:
        parts = [decoder.decode_page(frames, "SIM_TRUTH", part) for part in (0, 1, 2)]
    except DecodeError:
        parts = []
    if not parts or any(len(p["index"]) == 0 for p in parts):
        return _empty_poses()
    found = []
    for p in parts:
        keep = accepted[p["index"]]
        named = match_encoder(
            enc, p["index"][keep], p["ENC_COUNTER"][keep], p["timestamp_s"][keep], causal=False
        )
        uniq, first = _first_per_encoder(named)
        found.append((uniq, np.flatnonzero(keep)[first]))
    common = np.intersect1d(np.intersect1d(found[0][0], found[1][0]), found[2][0])
    pick = [f[1][np.searchsorted(f[0], common)] for f in found]
    heading_raw = parts[2]["HEADING"][pick[2]].astype(np.int64)
    return _Poses(
        enc=common.astype(np.int64),
        x_m=parts[0]["X"][pick[0]] * POSITION_LSB_M,
        y_m=parts[1]["Y"][pick[1]] * POSITION_LSB_M,
        heading_rad=heading_raw.astype(np.float64) * HEADING_LSB_RAD,
        heading_raw=heading_raw,
    )


def _empty_poses() -> _Poses:
    empty_f, empty_i = np.zeros(0), np.zeros(0, dtype=np.int64)
    return _Poses(empty_i, empty_f, empty_f, empty_f, empty_i)


# --- the reference --------------------------------------------------------------------------


@dataclass(frozen=True)
class _Reference:
    """The reference pose at every accepted encoder frame from the first on-board sample's on
    (element k: encoder frame ``start + k``)."""

    start: int  # index into _Encoders of the first on-board sample
    x_m: FloatArray
    y_m: FloatArray
    heading_rad: FloatArray
    distance_m: FloatArray
    restarts: int = 0  # gaps in the encoder sequence where the position was placed again
    exact_start: bool = False  # started at the power-up pose (0, 0, 0), not fitted
    counter_restarts: tuple[int, ...] = ()  # encoder frames the firmware re-primed on
    implausible_frames: int = 0  # encoder frames the firmware refuses (not integrated)

    def at(self, enc: IntArray) -> _Reference:
        """The reference at the encoder frames ``enc`` (all >= start)."""
        k = enc - self.start
        return _Reference(
            self.start, self.x_m[k], self.y_m[k], self.heading_rad[k], self.distance_m[k],
            self.restarts, self.exact_start, self.counter_restarts, self.implausible_frames,
        )


def _starts_at_power_up(
    frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder, onboard: _Poses
) -> bool:
    """The log starts at the firmware's power-up (module docstring, step 4): its first on-board
    sample names the first accepted encoder frame and reads exactly 0, and the first accepted
    ODOM_STATUS summary says UPTIME 0."""
    if int(onboard.enc[0]) != 0 or int(onboard.heading_raw[0]) != 0:
        return False
    if onboard.x_m[0] != 0.0 or onboard.y_m[0] != 0.0 or onboard.heading_rad[0] != 0.0:
        return False
    try:
        page = decoder.decode_page(frames, "ODOM_STATUS", 0)
    except DecodeError:
        return False
    if "UPTIME" not in page:
        return False
    uptime = page["UPTIME"][accepted[page["index"]]]
    return len(uptime) > 0 and int(uptime[0]) == 0 and _saw_only_the_log(frames, accepted, decoder)


def _saw_only_the_log(
    frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder
) -> bool:
    """Whether the firmware had accepted exactly the log's encoder frames when it sent its first
    ODOM_STATUS page of WHEEL_ENCODERS E2E counts (ENC_E2E_OK): then it primed on the log's first
    encoder frame. True when the log has no such page (other firmwares need not send it)."""
    try:
        page = decoder.decode_page(frames, "ODOM_STATUS", ENC_E2E_PAGE)
    except DecodeError:
        return True
    if "ENC_E2E_OK" not in page or not accepted[page["index"]].any():
        return True
    keep = accepted[page["index"]]
    first, ok = int(page["index"][keep][0]), int(page["ENC_E2E_OK"][keep][0])
    encoders = decoder.select(frames, "WHEEL_ENCODERS")
    in_log = int(np.count_nonzero(accepted[encoders] & (encoders < first)))
    return ok == in_log & 0xFFFF


def _reference(
    enc: _Encoders, onboard: _Poses, robot: RobotProfile, integrator: str, *, power_up: bool,
    max_wheel_speed_mm_s: int | None = MAX_WHEEL_SPEED_MM_S,
    breaks: IntArray | None = None,
) -> _Reference:
    """Integrate the encoder deltas from the first on-board sample on."""
    bits = min(robot.counter_bits, WIRE_COUNTER_BITS)
    e0 = int(onboard.enc[0])
    geometry = Geometry.of(robot)
    steps = _firmware_steps(enc, e0, geometry, bits, max_wheel_speed_mm_s)
    d_left, d_right = steps.d_left, steps.d_right
    rel = integrate(d_left, d_right, geometry, integrator)
    zero = np.zeros(1)
    rel_x, rel_y = np.concatenate((zero, rel.x_m)), np.concatenate((zero, rel.y_m))
    rel_h = np.concatenate((zero, rel.heading_rad))
    at = onboard.enc - e0
    starts = np.concatenate(([False], np.diff(enc.seq[e0:]) > 1))
    if breaks is not None:  # encoder frames where the firmware resumed after a stall
        inside = breaks[(breaks > e0) & (breaks < len(enc.seq))] - e0
        starts[inside] = True
    segment = np.cumsum(starts)
    x0, y0, h0, exact = _start_pose(
        onboard, _Relative(rel_x[at], rel_y[at], rel_h[at], segment[at]), power_up=power_up
    )
    cos0, sin0 = math.cos(h0), math.sin(h0)
    x_m = x0 + cos0 * rel_x - sin0 * rel_y
    y_m = y0 + sin0 * rel_x + cos0 * rel_y
    x_m += _segment_offsets(segment, at, onboard.x_m - x_m[at])
    y_m += _segment_offsets(segment, at, onboard.y_m - y_m[at])
    return _Reference(
        start=e0,
        x_m=x_m,
        y_m=y_m,
        heading_rad=h0 + rel_h,
        distance_m=np.concatenate((zero, rel.distance_m)),
        restarts=int(segment[-1]),
        exact_start=exact,
        counter_restarts=tuple(e0 + k for k in steps.reprimed),
        implausible_frames=steps.refused,
    )


@dataclass
class _Steps:
    """The count steps the firmware integrates between the accepted encoder frames of the log
    (element k: into frame ``e0 + k + 1``), with its refusals."""

    d_left: IntArray
    d_right: IntArray
    refused: int = 0  # frames beyond the plausibility bound, not integrated
    reprimed: list[int] = field(default_factory=list)  # frames (from e0) a counter restart primed


def _firmware_steps(
    enc: _Encoders, e0: int, geometry: Geometry, bits: int, max_wheel_speed_mm_s: int | None
) -> _Steps:
    """The steps as firmware/ecu.py takes them: a frame whose step from the last accepted one
    exceeds ``MAX_WHEEL_SPEED_MM_S`` over its periods is refused (IMPLAUSIBLE_STEP, not
    integrated); ``RESYNC_FRAMES`` refused frames plausible among themselves are a counter restart
    (COUNTER_RESET): the odometry re-primes on the first of them and integrates one step from it to
    the last. Vectorised; a short state machine runs only from each refused frame on. The bound is
    computed in float (the firmware's Q48 integer bound may differ by a count at the limit)."""
    left, right = enc.left[e0:], enc.right[e0:]
    seq = enc.seq[e0:]
    steps = _Steps(wrap_delta(np.diff(left), bits), wrap_delta(np.diff(right), bits))
    if max_wheel_speed_mm_s is None:
        return steps
    travel_m = max_wheel_speed_mm_s * 1e-3 * ENCODER_PERIOD_US * 1e-6
    bound = (math.ceil(travel_m / geometry.m_per_count_left) + 1,
             math.ceil(travel_m / geometry.m_per_count_right) + 1)

    def delta(a: int, b: int) -> tuple[int, int]:
        return (int(wrap_delta(int(left[b]) - int(left[a]), bits)),
                int(wrap_delta(int(right[b]) - int(right[a]), bits)))

    def plausible(a: int, b: int) -> bool:
        periods = max(1, int(seq[b] - seq[a]))
        d = delta(a, b)
        return abs(d[0]) <= periods * bound[0] and abs(d[1]) <= periods * bound[1]

    periods = np.maximum(1, np.diff(seq))
    bad = (np.abs(steps.d_left) > periods * bound[0]) | (np.abs(steps.d_right) > periods * bound[1])
    k = 0
    for first_bad in np.flatnonzero(bad).tolist():
        if first_bad + 1 <= k:
            continue  # handled by the state machine of an earlier refusal
        k = _refusals(steps, first_bad, len(left), plausible, delta)
    return steps


def _refusals(
    steps: _Steps,
    prev: int,
    n_frames: int,
    plausible: Any,
    delta: Any,
) -> int:
    """Run the firmware's refusal logic from frame ``prev + 1`` (``prev`` accepted) until a frame
    is accepted again; return that frame (``n_frames`` at the end of the log)."""
    resync_first: int | None = None
    resync_last = 0
    resync_frames = 0
    for k in range(prev + 1, n_frames):
        if plausible(prev, k):
            steps.d_left[k - 1], steps.d_right[k - 1] = delta(prev, k)
            return k
        steps.refused += 1
        steps.d_left[k - 1] = steps.d_right[k - 1] = 0
        if resync_first is not None and plausible(resync_last, k):
            resync_frames += 1
        else:
            resync_first, resync_frames = k, 1
        resync_last = k
        if resync_frames >= RESYNC_FRAMES:  # COUNTER_RESET: re-prime on the first, step to k
            steps.d_left[k - 1], steps.d_right[k - 1] = delta(resync_first, k)
            steps.reprimed.append(resync_first)
            return k
    return n_frames


def _segment_offsets(segment: IntArray, at: IntArray, error: FloatArray) -> FloatArray:
    """Position corrections per encoder frame after gaps in the encoder sequence.

    Across a gap the firmware may have integrated frames the log does not hold (a logger that
    missed them): the heading stays exact (a function of the absolute counts) but the position's
    path over the gap is unknown. Each segment after a gap is therefore placed like the start:
    the middle of the overlap of its on-board samples' rounding intervals (a segment without a
    sample keeps the previous correction). Segment 0 (the start) is not moved.
    """
    n_segments = int(segment[-1]) + 1
    offsets = np.full(n_segments, np.nan)
    offsets[0] = 0.0
    seg_of_sample = segment[at]
    bounds = np.searchsorted(seg_of_sample, np.arange(n_segments + 1))
    for k in np.flatnonzero(bounds[2:] > bounds[1:-1]) + 1:
        offsets[k] = _overlap_mid(error[bounds[k] : bounds[k + 1]], POSITION_LSB_M, base=True)
    filled = np.maximum.accumulate(np.where(np.isnan(offsets), 0, np.arange(n_segments)))
    result: FloatArray = offsets[filled][segment]
    return result


@dataclass(frozen=True)
class _Relative:
    """The reference's increments from the start to each on-board sample."""

    x_m: FloatArray
    y_m: FloatArray
    heading_rad: FloatArray
    segment: IntArray  # gaps of the encoder sequence before the sample


def _start_pose(
    onboard: _Poses, rel: _Relative, *, power_up: bool
) -> tuple[float, float, float, bool]:
    """The start pose (x m, y m, unwrapped heading rad) and whether it is the exact power-up pose
    (module docstring, step 4). The position uses only the samples before the first gap of the
    encoder sequence (the heading, exact across gaps, uses them all)."""
    n_first = max(1, int(np.searchsorted(rel.segment, 1)))
    h_first = onboard.heading_raw[0] * HEADING_LSB_RAD
    offsets = _wrap_pi(onboard.heading_raw * HEADING_LSB_RAD - rel.heading_rad - h_first)
    lo = float(np.max(offsets)) - 0.5 * HEADING_LSB_RAD
    hi = float(np.min(offsets)) + 0.5 * HEADING_LSB_RAD
    if power_up:
        return 0.0, 0.0, 0.0, True
    if lo <= hi:  # consistent: the middle of the whole log's overlap, refined by the positions
        dh = 0.5 * (lo + hi)
        dh += _rotation_fit(onboard, rel, h_first + dh, (lo - dh, hi - dh))
    else:  # the samples disagree (a wrong firmware): place it on the first samples only
        dh = _overlap_mid(offsets[:START_FIT_SAMPLES], HEADING_LSB_RAD)
    h0 = h_first + dh
    n = min(START_FIT_SAMPLES, n_first)
    cos0, sin0 = math.cos(h0), math.sin(h0)
    px = cos0 * rel.x_m[:n] - sin0 * rel.y_m[:n]
    py = sin0 * rel.x_m[:n] + cos0 * rel.y_m[:n]
    x0 = onboard.x_m[0] + _overlap_mid(onboard.x_m[:n] - px - onboard.x_m[0], POSITION_LSB_M)
    y0 = onboard.y_m[0] + _overlap_mid(onboard.y_m[:n] - py - onboard.y_m[0], POSITION_LSB_M)
    turns = math.floor((onboard.heading_rad[0] - h_first) / (2 * math.pi) + 0.5)
    return float(x0), float(y0), float(h0 + turns * 2 * math.pi), False


def _rotation_fit(
    onboard: _Poses, rel: _Relative, h0: float, bounds: tuple[float, float]
) -> float:
    """The small rotation (rad) of the reference about the start that best fits the on-board
    positions (least squares over every sample, each segment between gaps of the encoder
    sequence with a position offset of its own), kept within ``bounds``. Linearised:
    R(h0 + d) q = R(h0) q + d (-q_y, q_x)."""
    cos0, sin0 = math.cos(h0), math.sin(h0)
    qx = cos0 * rel.x_m - sin0 * rel.y_m
    qy = sin0 * rel.x_m + cos0 * rel.y_m
    bx = onboard.x_m - onboard.x_m[0] - qx
    by = onboard.y_m - onboard.y_m[0] - qy
    # normal equations of [1 0 -qy; 0 1 qx] (x_s, y_s, d) = (bx, by): offsets eliminated
    qx_c, qy_c, bx_c, by_c = (_centred(v, rel.segment) for v in (qx, qy, bx, by))
    spread = float(np.dot(qx_c, qx_c) + np.dot(qy_c, qy_c))
    if spread <= (POSITION_LSB_M * POSITION_LSB_M) * len(qx):  # no lever arm: nothing to learn
        return 0.0
    d = float(np.dot(qx_c, by_c) - np.dot(qy_c, bx_c)) / spread
    return min(max(d, bounds[0]), bounds[1])


def _centred(values: FloatArray, segment: IntArray) -> FloatArray:
    """``values`` less the mean of their segment."""
    sums = np.bincount(segment, weights=values)
    counts = np.maximum(np.bincount(segment), 1)
    centred: FloatArray = values - (sums / counts)[segment]
    return centred


def _overlap_mid(offsets: FloatArray, lsb: float, *, base: bool = False) -> float:
    """Middle of the overlap of [o - lsb/2, o + lsb/2] over ``offsets``, kept within the first
    interval (around 0, or around ``offsets[0]`` with ``base``)."""
    first = float(offsets[0]) if base else 0.0
    lo = float(np.max(offsets)) - 0.5 * lsb
    hi = float(np.min(offsets)) + 0.5 * lsb
    return min(max(0.5 * (lo + hi), first - 0.5 * lsb), first + 0.5 * lsb)


def _wrap_pi(angle: FloatArray) -> FloatArray:
    """Wrap to (-pi, pi], the one convention (``odocan.sim.truth.wrap_angle`` for arrays)."""
    wrapped: FloatArray = math.pi - (math.pi - angle) % (2 * math.pi)
    return wrapped


# --- errors and the report --------------------------------------------------------------------


def _errors(onboard: _Poses, ref: _Reference) -> tuple[FloatArray, FloatArray]:
    """Position (m) and wrapped heading (rad) errors, on-board minus reference (at the same
    encoder frames), per sample."""
    position = np.hypot(onboard.x_m - ref.x_m, onboard.y_m - ref.y_m)
    heading = _wrap_pi(onboard.heading_raw * HEADING_LSB_RAD - ref.heading_rad)
    return position, heading


def _summary(position: FloatArray, heading: FloatArray) -> dict[str, Any]:
    """Max and final errors (None when there is no sample)."""
    if len(position) == 0:
        return dict.fromkeys(
            ("max_position_error_m", "max_heading_error_rad", "final_position_error_m",
             "final_heading_error_rad"),
        )
    return {
        "max_position_error_m": float(np.max(position)),
        "max_heading_error_rad": float(np.max(np.abs(heading))),
        "final_position_error_m": float(position[-1]),
        "final_heading_error_rad": float(heading[-1]),
    }


def _versus_truth(
    onboard: _Poses, truth: _Poses, ref: _Reference
) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """On-board vs truth at every truth sample with an on-board sample at or after it."""
    estimate, keep = onboard_at(onboard, ref, truth.enc)
    position = np.hypot(estimate.x_m - truth.x_m[keep], estimate.y_m - truth.y_m[keep])
    heading = _wrap_pi(estimate.heading_rad - truth.heading_rad[keep])
    series = {
        "truth_enc": truth.enc[keep],
        "truth_x_m": truth.x_m[keep],
        "truth_y_m": truth.y_m[keep],
        "truth_heading_rad": truth.heading_rad[keep],
        "truth_position_error_m": position,
        "truth_heading_error_rad": heading,
    }
    return _summary(position, heading), series


def onboard_at(onboard: _Poses, ref: _Reference, enc: IntArray) -> tuple[_Poses, IntArray]:
    """The on-board pose at encoder frames ``enc``: the on-board sample there, or else the
    reference there plus (on-board - reference) at the nearest following on-board sample.

    The firmware sends its pose every other encoder frame (ODOM_POSE_* every 20 ms), so a truth
    sample may fall between two; the reference carries the on-board pose back by the one encoder
    step, exactly as the firmware integrated it (within the on-board vs reference tolerance).
    Returns the poses and the positions in ``enc`` that have one.
    """
    following = np.searchsorted(onboard.enc, enc)
    keep = np.flatnonzero((following < len(onboard.enc)) & (enc >= ref.start))
    s = following[keep]
    here, there = ref.at(enc[keep]), ref.at(onboard.enc[s])
    heading = onboard.heading_raw[s] * HEADING_LSB_RAD
    poses = _Poses(
        enc=enc[keep],
        x_m=onboard.x_m[s] - there.x_m + here.x_m,
        y_m=onboard.y_m[s] - there.y_m + here.y_m,
        heading_rad=np.asarray(heading - there.heading_rad + here.heading_rad, dtype=np.float64),
        heading_raw=onboard.heading_raw[s],
    )
    return poses, keep


def _robot_dict(robot: RobotProfile) -> dict[str, Any]:
    return {
        "name": robot.name,
        "counts_per_rev": robot.counts_per_rev,
        "wheel_radius_left_m": robot.wheel_radius_left_m,
        "wheel_radius_right_m": robot.wheel_radius_right_m,
        "wheelbase_m": robot.wheelbase_m,
        "counter_bits": robot.counter_bits,
    }


def _covered_s(frames: FrameArrays, db: cantools.database.can.Database) -> float:
    """Seconds of bus time the log covers: its encoder periods (first to last encoder frame,
    plus one cycle), or the plain frame span when it has no encoder frame."""
    message = db.get_message_by_name("WHEEL_ENCODERS")
    stamps = frames.timestamp_s[frames.can_id == message.frame_id]
    if len(stamps) == 0 or not message.cycle_time:
        return _span(frames)
    return float(stamps[-1] - stamps[0]) + message.cycle_time / 1000.0


def _span(frames: FrameArrays) -> float:
    """Seconds from the first to the last frame."""
    if len(frames) == 0:
        return 0.0
    return float(frames.timestamp_s[-1] - frames.timestamp_s[0])


def _realtime(sim_s: float, wall_s: float | None) -> float | None:
    """Simulated seconds per wall-clock second."""
    if wall_s is None or wall_s <= 0:
        return None
    return sim_s / wall_s


def _frame_counts(frames: FrameArrays, decoder: BulkDecoder) -> dict[str, int]:
    """Frames per DBC message in the log (whatever their E2E status)."""
    counts = {}
    for message in decoder.db.messages:
        n = len(decoder.select(frames, message.name))
        if n:
            counts[message.name] = n
    return counts


# --- the twist: ODOM_TWIST against the reference's speeds ------------------------------------

TWIST_LSB = 1e-3  # LINEAR_VEL 1 mm/s, ANGULAR_VEL 1 mrad/s
TWIST_RELATIVE = 0.02  # the firmware's dt is its own tick time: a late frame may shift it a bit
TWIST_RANGE = (-32.768, 32.767)  # both signals: i16 LSBs, saturated by the sender
TWIST_GAP_ACCEL_MPS2 = 5.0  # rim acceleration bound inside a step the log holds only in part


def check_twist(
    frames: FrameArrays,
    accepted: npt.NDArray[np.bool_],
    decoder: BulkDecoder,
    enc: _Encoders,
    robot: RobotProfile,
) -> dict[str, Any]:
    """ODOM_TWIST (LINEAR_VEL, ANGULAR_VEL) against the reference's speeds.

    The firmware reports the mean speed over its steps since its previous twist; a mean lies
    between the smallest and largest per-period speed it averages. So each twist frame must lie
    in the band of the reference's per-step speeds (step distance and heading change over its
    encoder periods) over the encoder frames since the twist frame before the previous one
    (twist frames come every other period), widened by one LSB plus ``TWIST_RELATIVE``. A
    twist from a wrong dt (e.g. 17 x the speed after 16 lost frames) falls far outside. Where
    the log lacks encoder frames the firmware may have had, a step of n periods only gives the
    mean of its periods: the band widens there by one count per period (quantisation) and
    ``TWIST_GAP_ACCEL_MPS2`` over the n - 1 periods. A log without ODOM_TWIST passes with 0
    samples.
    """
    try:
        twist = decoder.decode(frames, "ODOM_TWIST")
    except DecodeError:
        twist = {"index": np.zeros(0, dtype=np.int64)}
    keep = accepted[twist["index"]] if len(twist["index"]) else np.zeros(0, dtype=bool)
    result: dict[str, Any] = {
        "samples": 0,
        "max_linear_excess_mps": 0.0,
        "max_angular_excess_rad_s": 0.0,
        "passed": True,
    }
    if not keep.any():
        return result
    index = twist["index"][keep]
    e = match_encoder(enc, index, twist["ENC_COUNTER"][keep].astype(np.int64),
                      frames.timestamp_s[index], twist["COUNTER"][keep].astype(np.int64))
    ok = (e >= 0) & (e >= np.maximum.accumulate(e))
    e = e[ok]
    linear = twist["LINEAR_VEL"][keep][ok] * TWIST_LSB
    angular = twist["ANGULAR_VEL"][keep][ok] * TWIST_LSB
    (v_ref, w_ref), (v_gap, w_gap) = _step_speeds(enc, robot, decoder)
    excess_v = _outside_band(linear, e, v_ref, v_gap)
    excess_w = _outside_band(angular, e, w_ref, w_gap)
    judged = ~np.isnan(excess_v)
    result["samples"] = int(np.count_nonzero(judged))
    if result["samples"]:
        result["max_linear_excess_mps"] = float(np.max(excess_v[judged]))
        result["max_angular_excess_rad_s"] = float(np.max(excess_w[judged]))
        result["passed"] = bool(
            result["max_linear_excess_mps"] == 0.0 and result["max_angular_excess_rad_s"] == 0.0
        )
    return result


def _step_speeds(
    enc: _Encoders, robot: RobotProfile, decoder: BulkDecoder
) -> tuple[tuple[FloatArray, FloatArray], tuple[FloatArray, FloatArray]]:
    """Per accepted encoder frame j >= 1: the reference's linear (m/s) and angular (rad/s) speed
    over the step from frame j - 1, spread over its periods (element 0: NaN); and how far a
    single period inside a step of several may differ from that mean (0 for one period)."""
    g = Geometry.of(robot)
    bits = min(robot.counter_bits, WIRE_COUNTER_BITS)
    ds_left = wrap_delta(np.diff(enc.left), bits) * g.m_per_count_left
    ds_right = wrap_delta(np.diff(enc.right), bits) * g.m_per_count_right
    cycle_s = contract_cycle_s(decoder, "WHEEL_ENCODERS") or 0.01
    periods = np.diff(enc.seq)
    dt_s = periods * cycle_s
    nan = np.full(1, np.nan)
    v = np.concatenate((nan, 0.5 * (ds_left + ds_right) / dt_s))
    w = np.concatenate((nan, (ds_right - ds_left) / g.wheelbase_m / dt_s))
    count_mps = max(g.m_per_count_left, g.m_per_count_right) / cycle_s
    accel_mps = TWIST_GAP_ACCEL_MPS2 * (periods - 1) * cycle_s
    gap_v = np.concatenate(([0.0], np.where(periods > 1, count_mps + accel_mps, 0.0)))
    gap_w = gap_v * (2.0 / g.wheelbase_m)
    return (v, w), (gap_v, gap_w)


def _outside_band(value: FloatArray, e: IntArray, step: FloatArray, gap: FloatArray) -> FloatArray:
    """How far each ``value`` (at encoder frame ``e``) lies outside the band of ``step`` over
    (e two samples back, e], widened by the largest ``gap`` there: 0 inside, NaN where the
    window is empty."""
    out = np.full(len(value), np.nan)
    if len(e) < 3:
        return out
    step, gap = step[: int(e[-1]) + 1], gap[: int(e[-1]) + 1]
    starts = np.minimum(e[:-1] + 1, len(step) - 1)
    empty = e[1:] < e[:-1] + 1  # segment k: steps (e[k], e[k + 1]]
    seg_lo = np.where(empty, np.inf, np.minimum.reduceat(step, starts))
    seg_hi = np.where(empty, -np.inf, np.maximum.reduceat(step, starts))
    seg_gap = np.where(empty, 0.0, np.maximum.reduceat(gap, starts))
    lo = np.minimum(seg_lo[:-1], seg_lo[1:])
    hi = np.maximum(seg_hi[:-1], seg_hi[1:])
    known = np.isfinite(lo) & np.isfinite(hi)  # the window holds a step
    lo, hi = np.clip(lo, *TWIST_RANGE), np.clip(hi, *TWIST_RANGE)
    slack = TWIST_LSB + TWIST_RELATIVE * np.maximum(np.abs(lo), np.abs(hi))
    slack += np.maximum(seg_gap[:-1], seg_gap[1:])
    v = value[2:]
    excess = np.maximum(0.0, np.maximum(v - hi - slack, lo - slack - v))
    out[2:] = np.where(known, excess, np.nan)
    return out


# --- series for the plots (time axis, unwrapped headings, truth errors, gaps) ------------------


def plot_series(
    frames: FrameArrays, enc: _Encoders, onboard: _Poses, truth: _Poses, ref: _Reference
) -> dict[str, np.ndarray]:
    """What the plots need beyond the verdict's series (all times in s since the log's first
    frame, distances in m along the reference):

    * ``t_s``, ``onboard_seq``: time and encoder sequence number of each on-board sample;
      ``heading_error_unwrapped_rad``: on-board (TURNS * 2 pi + HEADING) minus the reference's
      continuous heading: no +-pi sawtooth, exact across gaps too;
    * ``truth_t_s``, ``truth_seq``, ``truth_distance_m``, ``truth_heading_error_unwrapped_rad``,
      ``truth_dx_m``, ``truth_dy_m``: at each compared truth sample (the verdict's series has
      ``truth_position_error_m`` and the wrapped ``truth_heading_error_rad``; the components are
      truth minus on-board); SIM_TRUTH has no turn count, so its heading error is unwrapped by
      continuity (exact while it changes by less than pi between two compared samples);
    * ``gap_{start,end}_{t_s,distance_m}``: spans between consecutive on-board samples further
      apart in the encoder sequence than usual (dropped pose or encoder frames);
    * ``restart_t_s``, ``restart_distance_m``: where the reference was placed again after a gap
      in the encoder sequence.
    """
    t_first = float(frames.timestamp_s[0]) if len(frames) else 0.0
    enc_t = frames.timestamp_s[enc.index] - t_first
    estimate, keep = onboard_at(onboard, ref, truth.enc)
    t_enc = truth.enc[keep]
    truth_heading = _wrap_pi(estimate.heading_rad - truth.heading_rad[keep])
    gaps = _sample_gaps(enc.seq[onboard.enc])
    distance = ref.at(onboard.enc).distance_m
    restart_enc = ref.start + 1 + np.flatnonzero(np.diff(enc.seq[ref.start :]) > 1)
    return {
        "t_s": enc_t[onboard.enc],
        "onboard_seq": enc.seq[onboard.enc],
        "heading_error_unwrapped_rad": onboard.heading_rad - ref.at(onboard.enc).heading_rad,
        "truth_t_s": enc_t[t_enc],
        "truth_seq": enc.seq[t_enc],
        "truth_distance_m": ref.at(t_enc).distance_m,
        "truth_heading_error_unwrapped_rad": np.unwrap(truth_heading),
        "truth_dx_m": truth.x_m[keep] - estimate.x_m,
        "truth_dy_m": truth.y_m[keep] - estimate.y_m,
        "gap_start_t_s": enc_t[onboard.enc[gaps]],
        "gap_end_t_s": enc_t[onboard.enc[gaps + 1]],
        "gap_start_distance_m": distance[gaps],
        "gap_end_distance_m": distance[gaps + 1],
        "restart_t_s": enc_t[restart_enc],
        "restart_distance_m": ref.at(restart_enc).distance_m,
    }


def _sample_gaps(seq: IntArray) -> IntArray:
    """Positions i where samples i and i + 1 are further apart in the encoder sequence than the
    usual (median) step: a frame was dropped between them."""
    steps = np.diff(seq)
    if len(steps) == 0:
        return np.zeros(0, dtype=np.int64)
    usual = max(1, int(np.median(steps)))
    return np.flatnonzero(steps > usual).astype(np.int64)
