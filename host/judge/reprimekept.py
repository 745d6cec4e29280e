"""What a bare APPLY kept after a firmware re-primed at a stall before its first pose (issue #11:
"a PASS/OK must never hide a wrong pose").

A rebooted firmware that halts before its first pose long enough for its step bound to reach the
ambiguous step re-primes on the frame it takes on resuming and says so (COUNTER_RESET:
``host.judge.stallreprime``): the stall's motion is not in its pose, by design. Its pose is then
its power-up pose (0, 0, 0) moved by the frames it took before the stall (its receive FIFO's,
up to ``stallreprime.FIFO_SPAN`` after its last frame before the silence) and by those from the
frame it re-primed on (at most ``stallreprime.R_SPAN`` before its first pose after the stall).
A bare APPLY then (nothing staged in the life: a reboot emptied the staging) commands that pose
kept; a staged field is commanded exactly. ``setposekept`` left such an APPLY unjudged (the
merged-steps rule from the power-up does not hold across a re-prime), and the life after it was
judged from a fitted start: a firmware that moved its X by 1 m there PASSed ``analyze``.

Which frames the firmware took is not on the log, so the pose at the APPLY's frame C is bounded,
not pinned: the first sample after the APPLY, moved back to C by the plain steps between (its
heading moved back by their turn), must lie within ``reach`` of the power-up pose: the travel
(and turn) of every frame the firmware can have integrated (the larger wheel's per frame, the
wheels' difference over the wheelbase), plus the sample's rounding (half an LSB, and its heading's
over the path back) - per field kept; a staged field within the rounding of its value. A correct
firmware is inside whichever frames it took; a jump beyond FAILs. A jump within the bound (a
robot moving while the FIFO filled or after the re-prime) cannot be told from the frames taken:
the check's ``bound_m`` says how coarse it is (the verdict line names it, never a silent PASS:
``host.report.summary.kept_unjudged``)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.keptjump import FLOAT_M, FLOAT_RAD, TURN_RAD
from odocan.host.judge.livesetpose import FIELDS
from odocan.host.judge.nearthreshold import COUNTER_RESET_BIT, ResetLog
from odocan.host.judge.reference import integrate
from odocan.host.judge.samples import (
    HEADING_LSB_RAD,
    POSITION_LSB_M,
    SILENCE_CYCLES,
    Encoders,
    FloatArray,
    IntArray,
    Poses,
)
from odocan.host.judge.stallreprime import FIFO_SPAN, R_SPAN
from odocan.host.protocol.decode import BulkDecoder

if TYPE_CHECKING:
    from odocan.host.judge.reference import Geometry
    from odocan.host.judge.setposekept import Odo

NOT_TOLD = ("the firmware said it left a step out (IMPLAUSIBLE_STEP, COUNTER_RESET), not that "
            "it re-primed at the stall before its first pose")
NOT_MADE = ("the firmware re-primed after a stall before its first pose (COUNTER_RESET), and "
            "the frames around the APPLY not all heard")


def reprime_kept(seen: tuple[Poses, Encoders, FloatArray], alive_s: FloatArray, c: int,
                 after: int, staged: dict[str, float], odo: Odo,
                 summaries: tuple[FloatArray, IntArray]) -> dict[str, Any] | str:
    """The module docstring's check of the APPLY that took effect after encoder frame ``c``
    (positions in the frames read, from the life's first), judged on the sample ``after``;
    ``alive_s``: the firmware's ODOM_STATUS bus times; ``odo``: ``setposekept.Odo``;
    ``summaries``: their bus times and ERROR_MASKs (``summaries_of``). Why not (words) when
    the firmware did not say it re-primed at this stall, or the frames cannot bound it."""
    poses, enc, sent_s = seen
    geometry, bits = odo.geometry, odo.bits
    first = int(np.argmin(sent_s))
    talked_s = _stall_start_s(alive_s, sent_s, float(sent_s[first]), enc.cycle_s)
    a = int(poses.enc[after])
    if talked_s is None or not _told(summaries, talked_s, float(sent_s[first])):
        return NOT_TOLD
    if a <= c or np.any(np.diff(enc.seq[: a + 1]) != 1):
        return NOT_MADE
    f_max = int(np.searchsorted(enc.timestamp_s, talked_s, side="right")) - 1 + FIFO_SPAN
    r_min = max(0, int(poses.enc[first]) - R_SPAN)
    d_left = wrapped(np.diff(enc.left[: a + 1]), bits)
    d_right = wrapped(np.diff(enc.right[: a + 1]), bits)
    taken = np.zeros(len(d_left), dtype=bool)  # step k: into frame k + 1
    taken[: max(0, min(f_max, c))] = True
    taken[r_min:c] = True
    travel_m, turn_rad = travel(d_left[taken], d_right[taken], geometry)
    after_pose = (float(poses.x_m[after]), float(poses.y_m[after]),
                  float(poses.heading_rad[after]))
    return from_after(after_pose, (d_left[c:], d_right[c:]), (travel_m, turn_rad), staged, odo)


def travel(d_left: IntArray, d_right: IntArray, geometry: Geometry) -> tuple[float, float]:
    """How far (m) and how much (rad) the steps (counts) can move the pose, whichever of them
    a firmware integrated, merged or not: the larger wheel's travel, the wheels' difference
    over the wheelbase, summed."""
    travel_m = np.maximum(np.abs(d_left) * geometry.m_per_count_left,
                          np.abs(d_right) * geometry.m_per_count_right)
    turn_rad = np.abs(d_right * geometry.m_per_count_right - d_left * geometry.m_per_count_left
                      ) / geometry.wheelbase_m
    return float(np.sum(travel_m)), float(np.sum(turn_rad))


def from_after(after: tuple[float, float, float], steps: tuple[IntArray, IntArray],
               reach: tuple[float, float], staged: dict[str, float], odo: Odo
               ) -> dict[str, Any]:
    """The check on the sample ``after`` (x m, y m, heading rad), moved back to the APPLY's
    frame by ``steps`` (counts from it), against the power-up pose within ``reach`` (m, rad:
    ``travel`` of the frames the firmware can have integrated); analyze's and ``livekept``'s."""
    rel = integrate(*steps, odo.geometry, odo.integrator)
    mx, my, mh = float(rel.x_m[-1]), float(rel.y_m[-1]), float(rel.heading_rad[-1])
    h_c = after[2] - mh
    x_c = after[0] - (math.cos(h_c) * mx - math.sin(h_c) * my)
    y_c = after[1] - (math.sin(h_c) * mx + math.cos(h_c) * my)
    round_m = 0.5 * POSITION_LSB_M + 0.5 * HEADING_LSB_RAD * math.hypot(mx, my) + FLOAT_M
    round_rad = 0.5 * HEADING_LSB_RAD + FLOAT_RAD
    return _judged((x_c, y_c, h_c), staged, reach, (round_m, round_rad), len(steps[0]))


def _judged(at_c: tuple[float, float, float], staged: dict[str, float],
            reach: tuple[float, float], rounding: tuple[float, float],
            frames: int) -> dict[str, Any]:
    """The check's result: the pose at the APPLY ``at_c`` against the power-up pose (kept
    fields, within ``reach`` plus ``rounding``: m, rad) or the staged value (within the
    ``rounding`` alone)."""
    round_m, round_rad = rounding
    bound_m, bound_rad = reach[0] + round_m, reach[1] + round_rad
    x_c, y_c, h_c = at_c
    want = (staged.get("X", 0.0), staged.get("Y", 0.0), staged.get("HEADING", 0.0))
    dx, dy = x_c - want[0], y_c - want[1]
    dh = abs((h_c - want[2] + math.pi) % TURN_RAD - math.pi)
    kept_m = math.hypot(dx if "X" not in staged else 0.0, dy if "Y" not in staged else 0.0)
    passed = kept_m <= bound_m and (dh <= bound_rad or "HEADING" in staged)
    for k, name in enumerate(("X", "Y")):
        passed &= name not in staged or abs((dx, dy)[k]) <= round_m
    if "HEADING" in staged:
        passed &= dh <= round_rad
    return {"fields_kept": [name for name in FIELDS if name not in staged],
            "encoder_frames": frames, "position_jump_m": math.hypot(dx, dy),
            "heading_jump_rad": dh, "bound_m": bound_m, "passed": bool(passed),
            "reprimed": True}


def summaries_of(frames: FrameArrays, accepted: np.ndarray,
                 decoder: BulkDecoder) -> tuple[FloatArray, IntArray]:
    """The bus times and ERROR_MASKs of the accepted summaries of ``frames`` (none when the
    DBC has no ERROR_MASK: nothing told)."""
    log = ResetLog()
    log.feed(frames, decoder, np.flatnonzero(accepted))
    if not log.usable or not log.sent_s:
        return np.zeros(0), np.zeros(0, dtype=np.int64)
    return np.concatenate(log.sent_s), np.concatenate(log.mask)


def _told(summaries: tuple[FloatArray, IntArray], talked_s: float, first_s: float) -> bool:
    """Whether the firmware said it re-primed at the stall from ``talked_s`` to its first
    sample at ``first_s``: COUNTER_RESET clear on its last summary before the stall, set on
    one after (``nearthreshold.Resets.told``'s rule); a refusal said elsewhere is no re-prime
    here (the firmware then took the stall merged, far from the bound)."""
    sent_s, mask = summaries
    before, later = mask[sent_s <= talked_s], mask[sent_s > first_s]
    return (len(before) > 0 and not int(before[-1]) & COUNTER_RESET_BIT
            and bool(np.any(later & COUNTER_RESET_BIT)))


def _stall_start_s(alive_s: FloatArray, sent_s: FloatArray, first_s: float,
                   cycle_s: float | None) -> float | None:
    """The bus time of the firmware's last frame before the silence that ended at its first
    sample ``first_s`` (``SILENCE_CYCLES`` cycles or more); None when there is none."""
    if cycle_s is None:
        return None
    times = np.sort(np.concatenate((alive_s, sent_s)))
    times = times[times <= first_s]
    gaps = np.flatnonzero(np.diff(times) >= SILENCE_CYCLES * cycle_s)
    return float(times[gaps[-1]]) if len(gaps) else None


def wrapped(delta: np.ndarray, bits: int) -> np.ndarray:
    """Count steps read in ``bits``-bit counters (signed)."""
    half = 1 << (bits - 1)
    out: np.ndarray = (delta.astype(np.int64) + half) % (2 * half) - half
    return out
