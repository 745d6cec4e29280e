"""Resent poses (issue #11): every pose frame the firmware sends is judged, not only the first
naming an encoder frame (``samples.onboard_samples``' sample).

A firmware that ticks without a new encoder frame (lost frames, a hold) sends its pose again
naming the same ENC_COUNTER; a frame after a lost pose frame may name an encoder frame named
before too. Within one firmware life (``host.judge.reboots``, ``host.judge.setposes``: a reboot
or an applied set-pose starts a new one) nothing moves the pose but an encoder frame, so each
such frame must equal the reference at the frame it names, as the first does. A resent half
(ODOM_POSE_X: X and HEADING; ODOM_POSE_Y: Y and TURNS) is judged with the sample's other half
at that encoder frame (the pair of a resend may be split across ticks: each half is judged on
its own). ``worst_sent`` puts in each sample the worst pose the firmware sent for its encoder
frame, so the judge's errors (and everything after it: allowances, truth) see it. A correct
firmware's resends equal the sample: nothing changes (the samples are returned as they are).

The streamed analysis cannot put a resend in a sample given out chunks before it (``resent``:
``stream_analysis`` refuses such a life, ``NotStreamable``, and the whole log's path judges it).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from odocan.host.judge.compare import pose_errors
from odocan.host.judge.reference_path import Reference
from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M, PoseHalves, Poses


def worst_sent(onboard: Poses, halves: PoseHalves, ref_all: Reference,
               tolerance_m: float, tolerance_rad: float) -> Poses:
    """``onboard`` with each sample replaced by the pose frame naming its encoder frame that is
    farthest from the reference there (the larger of position / ``tolerance_m`` and heading /
    ``tolerance_rad``), when that is not the sample itself."""
    alt = resent_poses(onboard, halves)
    if len(alt.enc) == 0:
        return onboard
    pos, head = pose_errors(alt, ref_all.at(alt.enc))
    bad = np.maximum(pos / tolerance_m, np.abs(head) / tolerance_rad)
    pos0, head0 = pose_errors(onboard, ref_all.at(onboard.enc))
    bad0 = np.maximum(pos0 / tolerance_m, np.abs(head0) / tolerance_rad)
    k = np.searchsorted(onboard.enc, alt.enc)
    x_m: npt.NDArray[np.float64] = onboard.x_m.copy()
    y_m: npt.NDArray[np.float64] = onboard.y_m.copy()
    heading_rad: npt.NDArray[np.float64] = onboard.heading_rad.copy()
    heading_raw: npt.NDArray[np.int64] = onboard.heading_raw.copy()
    worst = bad0.copy()
    for i in np.argsort(bad, kind="stable").tolist():  # the worst last: it stays
        if bad[i] > worst[k[i]]:
            worst[k[i]] = bad[i]
            x_m[k[i]], y_m[k[i]] = alt.x_m[i], alt.y_m[i]
            heading_rad[k[i]], heading_raw[k[i]] = alt.heading_rad[i], alt.heading_raw[i]
    return Poses(onboard.enc, x_m, y_m, heading_rad, heading_raw)


def resent_poses(onboard: Poses, halves: PoseHalves) -> Poses:
    """The pose frames naming a sample's encoder frame that differ from the sample's half of
    their kind, each with the sample's other half (in frame order, X frames first)."""
    k_x, same_x = _differing(onboard, _unaliased(halves.ex, halves.ax))
    k_y, same_y = _differing(onboard, _unaliased(halves.ey, halves.ay))
    x_raw = halves.px["X"][same_x].astype(np.int64)
    heading_raw = halves.px["HEADING"][same_x].astype(np.int64)
    keep_x = (x_raw * POSITION_LSB_M != onboard.x_m[k_x]) | (heading_raw
                                                            != onboard.heading_raw[k_x])
    y_raw = halves.py["Y"][same_y].astype(np.int64)
    turns = halves.py["TURNS"][same_y].astype(np.int64)
    keep_y = (y_raw * POSITION_LSB_M != onboard.y_m[k_y]) | (turns != _turns(onboard)[k_y])
    k_x, x_raw, heading_raw = k_x[keep_x], x_raw[keep_x], heading_raw[keep_x]
    k_y, y_raw, turns = k_y[keep_y], y_raw[keep_y], turns[keep_y]
    sample_turns = _turns(onboard)
    all_heading_raw = np.concatenate((heading_raw, onboard.heading_raw[k_y]))
    all_turns = np.concatenate((sample_turns[k_x], turns))
    return Poses(
        enc=np.concatenate((onboard.enc[k_x], onboard.enc[k_y])),
        x_m=np.concatenate((x_raw * POSITION_LSB_M, onboard.x_m[k_y])),
        y_m=np.concatenate((onboard.y_m[k_x], y_raw * POSITION_LSB_M)),
        heading_rad=all_turns * 2 * math.pi + all_heading_raw * HEADING_LSB_RAD,
        heading_raw=all_heading_raw,
    )


def _differing(onboard: Poses, named: npt.NDArray[np.int64]) -> tuple[
        npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """The frames of one kind naming a sample's encoder frame: the sample (position in
    ``onboard``) and the frame (position among the kind's frames)."""
    k = np.minimum(np.searchsorted(onboard.enc, named), max(len(onboard.enc) - 1, 0))
    hit = (named >= 0) & (len(onboard.enc) > 0)
    if len(onboard.enc):
        hit &= onboard.enc[k] == named
    frames = np.flatnonzero(hit)
    return k[frames].astype(np.int64), frames.astype(np.int64)


def _unaliased(named: npt.NDArray[np.int64], alias: npt.NDArray[np.bool_] | None
               ) -> npt.NDArray[np.int64]:
    """``named`` with -1 where the half may name another frame (``host.judge.resendalias``)."""
    return named if alias is None else np.where(alias, -1, named)


def _turns(onboard: Poses) -> npt.NDArray[np.int64]:
    """The samples' TURNS (their heading is TURNS * 2 pi + HEADING)."""
    whole = (onboard.heading_rad - onboard.heading_raw * HEADING_LSB_RAD) / (2 * math.pi)
    return np.rint(whole).astype(np.int64)


def resent_differs(first: dict[str, float], again: dict[str, float]) -> bool:
    """Whether a pose frame naming an encoder frame a frame of its kind named before differs
    from that one (the streamed analysis: ``stream.StreamPoses``)."""
    return any(first[name] != again[name] for name in ("X", "HEADING", "Y", "TURNS")
               if name in first)
