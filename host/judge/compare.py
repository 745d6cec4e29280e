"""The comparisons: on-board vs reference and vs truth (errors and their summaries), ODOM_TWIST
against the reference's speeds, and the series the plots need (``host.judge.analysis`` module
docstring, step 5)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from odocan.firmware.clock import LOST_TIME_PERIODS
from odocan.host.io.logs import FrameArrays
from odocan.host.judge.ctrlrestart import ctrl_restarts
from odocan.host.judge.latenames import sent_places
from odocan.host.judge.reference import Geometry, wrap_delta
from odocan.host.judge.reference_path import Reference
from odocan.host.judge.samples import (
    HEADING_LSB_RAD,
    WIRE_COUNTER_BITS,
    Encoders,
    FloatArray,
    IntArray,
    Poses,
    contract_cycle_s,
    match_encoder,
    wrap_pi,
)
from odocan.host.judge.turns import unwrapped_errors
from odocan.host.protocol import busfacts
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.sim.robot import RobotProfile

# --- errors and the report --------------------------------------------------------------------


def pose_errors(onboard: Poses, ref: Reference) -> tuple[FloatArray, FloatArray]:
    """Position (m) and heading (rad) errors, on-board minus reference (at the same encoder
    frames), per sample: the heading's wrapped to (-pi, pi] plus 2 pi per whole turn TURNS is
    off (``host.judge.turns``)."""
    position = np.hypot(onboard.x_m - ref.x_m, onboard.y_m - ref.y_m)
    heading = wrap_pi(onboard.heading_raw * HEADING_LSB_RAD - ref.heading_rad)
    return position, unwrapped_errors(onboard.heading_rad, ref.heading_rad, heading)


def error_summary(position: FloatArray, heading: FloatArray) -> dict[str, Any]:
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


# --- the truth in a firmware life's frame ----------------------------------------------------


def life_origin(
    truth: tuple[float, float, float], ref: tuple[float, float, float]
) -> tuple[float, float, float]:
    """Where a firmware life's origin lies in the truth's frame: x (m), y (m), heading (rad).

    A rebooted firmware starts its pose at 0 at the encoder frame it primed on, so its frame is
    the truth's pose there. SIM_TRUTH comes every 100 ms, seldom at that very frame: the origin
    is taken at the life's first truth sample (``truth``: x, y, heading) carried back to the
    reference's start along the reference (``ref``: its pose at that sample's frame), the
    pose ``truth - ref`` composed: heading ``h_t - h_r``, position the truth's less the
    reference's rotated by that heading. At power-up (reference 0 at the primed frame) it is
    the truth at that frame, to within the odometry error of the few frames carried; where the
    life's start was fitted (its boot summary missed) it places the truth on the reference
    there, as the reference is placed on the on-board pose.
    """
    heading = truth[2] - ref[2]
    c, s = math.cos(heading), math.sin(heading)
    return (truth[0] - (c * ref[0] - s * ref[1]), truth[1] - (s * ref[0] + c * ref[1]), heading)


def rebase_truth(
    x_m: FloatArray, y_m: FloatArray, heading_rad: FloatArray,
    origin: tuple[float, float, float],
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The truth in the life's frame whose origin is ``origin`` (``life_origin``): its
    position less the origin's, rotated by minus the origin's heading; its heading less the
    origin's (rad). Element by element: the whole-log, streamed and live judges agree bit for
    bit on the same samples."""
    x0, y0, h0 = origin
    c, s = math.cos(h0), math.sin(h0)
    dx, dy = np.asarray(x_m, dtype=np.float64) - x0, np.asarray(y_m, dtype=np.float64) - y0
    return c * dx + s * dy, c * dy - s * dx, np.asarray(heading_rad, dtype=np.float64) - h0


def origin_dict(origin: tuple[float, float, float], truth_enc: int, ref_start: int
                ) -> dict[str, Any]:
    """The report's form of a life's truth origin (``life_origin``): the truth's pose taken
    as the life's (0, 0, 0), the life's encoder frame of the truth sample it came from and how
    many frames the reference carried it back."""
    return {"x_m": origin[0], "y_m": origin[1], "heading_rad": origin[2],
            "truth_encoder_frame": truth_enc, "carried_frames": truth_enc - ref_start}


def rebased_at_start(truth: Poses, ref: Reference) -> tuple[Poses, dict[str, Any] | None]:
    """``truth`` in the frame of the life whose reference is ``ref`` (``life_origin`` at its
    first truth sample from the reference's start on) and the origin's report; unchanged and
    None without such a sample."""
    first = np.flatnonzero(truth.enc >= ref.start)
    if len(first) == 0:
        return truth, None
    k = int(first[0])
    at = ref.at(truth.enc[k : k + 1])
    origin = life_origin(
        (float(truth.x_m[k]), float(truth.y_m[k]), float(truth.heading_rad[k])),
        (float(at.x_m[0]), float(at.y_m[0]), float(at.heading_rad[0])),
    )
    x, y, h = rebase_truth(truth.x_m, truth.y_m, truth.heading_rad, origin)
    rebased = Poses(enc=truth.enc, x_m=x, y_m=y, heading_rad=h, heading_raw=truth.heading_raw)
    return rebased, origin_dict(origin, int(truth.enc[k]), ref.start)


def versus_truth(
    onboard: Poses, truth: Poses, ref: Reference
) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """On-board vs truth at every truth sample with an on-board sample at or after it."""
    estimate, keep = onboard_at(onboard, ref, truth.enc)
    position = np.hypot(estimate.x_m - truth.x_m[keep], estimate.y_m - truth.y_m[keep])
    heading = wrap_pi(estimate.heading_rad - truth.heading_rad[keep])
    series = {
        "truth_enc": truth.enc[keep],
        "truth_x_m": truth.x_m[keep],
        "truth_y_m": truth.y_m[keep],
        "truth_heading_rad": truth.heading_rad[keep],
        "truth_position_error_m": position,
        "truth_heading_error_rad": heading,
    }
    return error_summary(position, heading), series


def onboard_at(onboard: Poses, ref: Reference, enc: IntArray) -> tuple[Poses, IntArray]:
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
    x_m, y_m, heading_rad = carried(
        (onboard.x_m[s], onboard.y_m[s], heading),
        (there.x_m, there.y_m, there.heading_rad), (here.x_m, here.y_m, here.heading_rad))
    poses = Poses(enc=enc[keep], x_m=x_m, y_m=y_m,
                  heading_rad=np.asarray(heading_rad, dtype=np.float64),
                  heading_raw=onboard.heading_raw[s])
    return poses, keep


def carried(onboard: tuple[Any, Any, Any], there: tuple[Any, Any, Any],
            here: tuple[Any, Any, Any]) -> tuple[Any, Any, Any]:
    """The on-board pose (x m, y m, heading rad) at the reference's ``there``, carried to its
    ``here`` by the reference's own motion between them, turned into the on-board pose's frame
    (by on-board heading - reference heading at ``there``): where the reference and the
    firmware part in heading (a reference that re-primed over a stall, a firmware off), the
    reference's step in its own direction is no step of the firmware's (6 mm off the truth on a
    correct firmware at 0.7 m/s). Element by element, arrays or floats: the whole-log, streamed
    and live judges carry alike."""
    turn = onboard[2] - there[2]
    c, s = np.cos(turn), np.sin(turn)
    dx, dy = here[0] - there[0], here[1] - there[1]
    return (onboard[0] + c * dx - s * dy, onboard[1] + s * dx + c * dy,
            onboard[2] - there[2] + here[2])



# --- the twist: ODOM_TWIST against the reference's speeds ------------------------------------

TWIST_LSB = 1e-3  # LINEAR_VEL 1 mm/s, ANGULAR_VEL 1 mrad/s
TWIST_RELATIVE = 0.02  # the firmware's dt is its own tick time: a late frame may shift it a bit
TWIST_RANGE = (-32.768, 32.767)  # both signals: i16 LSBs, saturated by the sender
TWIST_GAP_ACCEL_MPS2 = 5.0  # rim acceleration bound inside a step the log holds only in part
# twist frames this far apart (bus time): the firmware may have lost time between them
TWIST_SILENCE_S = (LOST_TIME_PERIODS - 0.5) * busfacts.ENC_CYCLE_S


def check_twist(
    frames: FrameArrays,
    accepted: npt.NDArray[np.bool_],
    decoder: BulkDecoder,
    enc: Encoders,
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
    ``TWIST_GAP_ACCEL_MPS2`` over the n - 1 periods. A resend (the same encoder frame named
    again) has the window of the frame that first named it, at any depth (``_outside_band``);
    after a silence of the firmware the band reaches 0 (``after_silence``: a stall's carried
    steps). A log without ODOM_TWIST passes with 0 samples.
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
    e = match_encoder(enc, *sent_places(frames, decoder, "ODOM_TWIST", index,
                                        frames.timestamp_s[index],
                                        twist["ENC_COUNTER"][keep].astype(np.int64)),
                      twist["COUNTER"][keep].astype(np.int64))  # a late one: where sent
    ok = (e >= 0) & (e >= np.maximum.accumulate(e))
    e = e[ok]
    linear = twist["LINEAR_VEL"][keep][ok] * TWIST_LSB
    angular = twist["ANGULAR_VEL"][keep][ok] * TWIST_LSB
    t_s = frames.timestamp_s[index][ok]
    silent = np.concatenate(([False], np.diff(t_s) >= TWIST_SILENCE_S))
    (v_ref, w_ref), (v_gap, w_gap) = _step_speeds(enc, robot, decoder)
    excess_v = _outside_band(linear, e, v_ref, v_gap, silent)
    excess_w = _outside_band(angular, e, w_ref, w_gap, silent)
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
    enc: Encoders, robot: RobotProfile, decoder: BulkDecoder
) -> tuple[tuple[FloatArray, FloatArray], tuple[FloatArray, FloatArray]]:
    """Per accepted encoder frame j >= 1: the reference's linear (m/s) and angular (rad/s) speed
    over the step from frame j - 1, spread over its periods (element 0: NaN); and how far a
    single period inside a step of several may differ from that mean (0 for one period)."""
    g = Geometry.of(robot)
    bits = min(robot.counter_bits, WIRE_COUNTER_BITS)
    ds_left = wrap_delta(np.diff(enc.left), bits) * g.m_per_count_left
    ds_right = wrap_delta(np.diff(enc.right), bits) * g.m_per_count_right
    cycle_s = contract_cycle_s(decoder, "WHEEL_ENCODERS") or busfacts.ENC_CYCLE_S
    periods = np.diff(enc.seq)
    dt_s = periods * cycle_s
    # Each series is built in place in its output, element 0 first (the same operations in the
    # same order as the one-line formulas in the comments: the same bits, a few full-size
    # temporaries instead of a dozen).
    v, w = np.empty(len(periods) + 1), np.empty(len(periods) + 1)
    v[0] = w[0] = np.nan
    np.add(ds_left, ds_right, out=v[1:])  # 0.5 * (ds_left + ds_right) / dt_s
    v[1:] *= 0.5
    v[1:] /= dt_s
    np.subtract(ds_right, ds_left, out=w[1:])  # (ds_right - ds_left) / wheelbase_m / dt_s
    w[1:] /= g.wheelbase_m
    w[1:] /= dt_s
    count_mps = max(g.m_per_count_left, g.m_per_count_right) / cycle_s
    gap_v = np.empty(len(periods) + 1)  # periods > 1: count_mps + 5.0 * (periods - 1) * cycle_s
    gap_v[0] = 0.0
    np.multiply(TWIST_GAP_ACCEL_MPS2, periods - 1, out=gap_v[1:])
    gap_v[1:] *= cycle_s
    gap_v[1:] += count_mps
    gap_v[1:][periods <= 1] = 0.0
    gap_w = gap_v * (2.0 / g.wheelbase_m)
    # A frame that waited on a busy bus came more periods after the one before than its COUNTER
    # step says: the firmware, which cannot tell waiting from losing, may spread the step over
    # the time it waited (its mean speed then lies between 0 and the step's speed).
    late_s = periods + 0.5
    late_s *= cycle_s
    waited = 1 + np.flatnonzero(np.diff(enc.timestamp_s) > late_s)
    gap_v[waited] = np.maximum(gap_v[waited], np.abs(v[waited]))
    gap_w[waited] = np.maximum(gap_w[waited], np.abs(w[waited]))
    if enc.uptime is not None:  # CTRL_UPTIME went back: a firmware may re-prime there, no step
        restarted = 1 + np.flatnonzero(ctrl_restarts(enc.uptime, np.ones(len(v), dtype=bool),
                                                     np.diff(enc.timestamp_s), enc.cycle_s,
                                                     enc.counter))
        v[restarted] = w[restarted] = np.nan  # a twist over it is not judged
    return (v, w), (gap_v, gap_w)


def _outside_band(value: FloatArray, e: IntArray, step: FloatArray, gap: FloatArray,
                  silent: npt.NDArray[np.bool_] | None = None) -> FloatArray:
    """How far each ``value`` (at encoder frame ``e``) lies outside the band of ``step`` over
    its window, widened by the largest ``gap`` there: 0 inside, NaN where the window is empty.

    The window of a twist frame naming D[i], the i-th distinct encoder frame named
    (``carried_windows``): (D[i - 2], D[i]], the steps over the last two twist periods that
    brought a new encoder frame. A resend (naming the frame the one before named, at any depth)
    has the window of the first naming that frame: the firmware's speeds then hold either the
    speeds it sent before or, after a tick that lost time, the mean over steps it carried, all
    within that window (``firmware.twist``: a stall's backlog, accepted before the frame the
    resends name); a resend of a resend is judged too."""
    out = np.full(len(value), np.nan)
    if len(e) < 3:
        return out
    # segment k: steps (e[k], e[k + 1]], the slices [e[k] + 1, e[k + 1] + 1) of ``reduceat``
    # (a closing start, e[-1] + 1, so that the last segment ends at e[-1] too: the one after it
    # is dropped, so the step there may be any, the next real one or, at the end, a padding 0)
    end = int(e[-1]) + 1
    if end < len(step):  # views: no copies
        step, gap = step[: end + 1], gap[: end + 1]
    else:
        pad = np.zeros(1)
        step, gap = np.concatenate((step[:end], pad)), np.concatenate((gap[:end], pad))
    starts = e + 1
    empty = e[1:] < e[:-1] + 1
    seg_lo = np.where(empty, np.inf, np.minimum.reduceat(step, starts)[:-1])
    seg_hi = np.where(empty, -np.inf, np.maximum.reduceat(step, starts)[:-1])
    seg_gap = np.where(empty, 0.0, np.maximum.reduceat(gap, starts)[:-1])
    # per frame k: its own segment (e[k - 1], e[k]] (frame 0: none, an empty band)
    own = tuple(np.concatenate(([first], seg)) for first, seg in
                ((np.inf, seg_lo), (-np.inf, seg_hi), (0.0, seg_gap)))
    head, before = carried_windows(np.concatenate(([False], empty)))
    a: tuple[FloatArray, ...] = tuple(np.where(before >= 0, x[np.maximum(before, 0)], first)
                                      for x, first in zip(own, (np.inf, -np.inf, 0.0),
                                                          strict=True))
    b: tuple[FloatArray, ...] = tuple(x[head] for x in own)
    zero = None if silent is None else after_silence(silent, head)
    excess = band_excess(value, a, b, zero)
    out[2:] = excess[2:]
    return out


def carried_windows(resent: npt.NDArray[np.bool_]) -> tuple[IntArray, IntArray]:
    """Per twist frame (``resent``: it names the frame the one before named; frame 0 never
    is): the frame that first named its encoder frame (the head of its chain of resends), and
    the head of the chain before (-1: none). A frame's window is its head's segment joined to
    that head's (``_outside_band``)."""
    n = len(resent)
    at = np.arange(n)
    head = np.maximum.accumulate(np.where(resent, 0, at))
    before_head = np.where(head >= 1, head[np.maximum(head - 1, 0)], -1)
    return head, before_head


def after_silence(silent: npt.NDArray[np.bool_], head: IntArray) -> npt.NDArray[np.bool_]:
    """Per twist frame: it is in the chain of resends of the first frame after a silence of the
    firmware (``silent``), or in the chain after it. A tick that lost time (a stall: the
    firmware silent ``LOST_TIME_PERIODS``) sums its steps on and divides them, in the first
    tick after it, by the firmware time since its last sample before the stall
    (``firmware.twist``): the backlog's frames may span less (a full mailbox drops the newest),
    so that speed lies between 0 and the steps' mean. The frames sending it: the chain of the
    frame after the silence (the update under its ENC_COUNTER, ``carried_windows``) or the
    chain after (the update with the next frames)."""
    at = np.arange(len(head))
    last = np.maximum.accumulate(np.where(silent, at, -1))
    heads = np.cumsum(head == at)
    found: npt.NDArray[np.bool_] = (last >= 0) & (heads - heads[np.maximum(last, 0)] <= 1)
    return found


def band_excess(value: FloatArray, a: tuple[FloatArray, ...], b: tuple[FloatArray, ...],
                zero: npt.NDArray[np.bool_] | None = None) -> FloatArray:
    """The excess of each value over the band of its window's two segments' bands ``a`` and
    ``b`` (lowest, highest speed, widest gap slack), the band reaching 0 where ``zero``
    (``after_silence``): 0 inside, NaN where neither holds a step (``host.judge.stream_twist``
    and ``host.judge.livetwist`` do these operations in this order: the same bits)."""
    lo = np.minimum(a[0], b[0])
    hi = np.maximum(a[1], b[1])
    known = np.isfinite(lo) & np.isfinite(hi)  # the window holds a step
    if zero is not None:
        lo, hi = np.where(zero, np.minimum(lo, 0.0), lo), np.where(zero, np.maximum(hi, 0.0), hi)
    lo, hi = np.clip(lo, *TWIST_RANGE), np.clip(hi, *TWIST_RANGE)
    slack = TWIST_LSB + TWIST_RELATIVE * np.maximum(np.abs(lo), np.abs(hi))
    slack += np.maximum(a[2], b[2])
    excess = np.maximum(0.0, np.maximum(value - hi - slack, lo - slack - value))
    out: FloatArray = np.where(known, excess, np.nan)
    return out


# --- series for the plots (time axis, unwrapped headings, truth errors, gaps) ------------------


def plot_series(
    frames: FrameArrays, enc: Encoders, onboard: Poses, truth: Poses, ref: Reference
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
    truth_heading = wrap_pi(estimate.heading_rad - truth.heading_rad[keep])
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
