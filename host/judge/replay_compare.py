"""The replayed firmware's on-board poses against the logged ones (``host.judge.replay``'s
``onboard_vs_log`` section, and the departures that fail a replay).

At each encoder frame both firmwares' poses name, the largest difference between any pose sent
naming it in the log and in the replay: positions up to the log's first gap of the encoder
sequence, after it their offset's drift between two gaps (when the log says its firmware took
its frames on time, ``replayable``), headings everywhere, and the log's resent positions against
its first at the same frame (one firmware's poses at one frame agree).
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
from odocan.host.judge.replay_track import EncoderTrack
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e import check_frames
from odocan.sim import contract


def onboard_by_tick(frames: FrameArrays, accepted: npt.NDArray[np.bool_]) -> dict[int, list[
        tuple[int, int, int]]]:
    """The on-board poses of ``frames`` by the tick of the encoder frame they name:
    (X raw, Y raw, heading in BAM16 units unwrapped = TURNS * 65536 + HEADING); the first X
    with the first Y, then each other X and Y sent naming it (a resend: every pose frame is
    compared, each half with the first of the other kind, as ``host.judge.resent``)."""
    decoder = BulkDecoder(contract.database())
    track = EncoderTrack.of(frames, accepted, decoder)
    halves = []
    for name, value, extra in (("ODOM_POSE_X", "X", "HEADING"), ("ODOM_POSE_Y", "Y", "TURNS")):
        d = decoder.decode(frames, name)
        keep = accepted[d["index"]]
        ticks = track.named(d["index"][keep], d["ENC_COUNTER"][keep].astype(np.int64),
                            d["timestamp_s"][keep])
        half: dict[int, list[tuple[int, int]]] = {}
        previous = -1  # a resend names its predecessor's frame (one naming an earlier one
        for tick, v, e in zip(ticks.tolist(), d[value][keep].tolist(), d[extra][keep].tolist(),
                              strict=True):  # after a gap of the log's frames is no resend)
            sent = half.setdefault(tick, []) if tick >= 0 else []
            if (not sent or tick == previous) and (int(v), int(e)) not in sent:
                sent.append((int(v), int(e)))
            previous = tick
        halves.append(half)
    px, py = halves
    return {t: [(x, py[t][0][0], py[t][0][1] * 65536 + h) for x, h in px[t]]
            + [(px[t][0][0], y, turns * 65536 + px[t][0][1]) for y, turns in py[t][1:]]
            for t in px.keys() & py.keys()}


def versus_log(
    log: FrameArrays, log_accepted: npt.NDArray[np.bool_], replayed: FrameArrays
) -> dict[str, Any]:
    """The replayed on-board poses against the logged ones at the same encoder frames (at each,
    the largest difference between any pose sent naming it in the log and in the replay)."""
    _, accepted = check_frames(replayed)
    old, new = onboard_by_tick(log, log_accepted), onboard_by_tick(replayed, accepted)
    common = sorted(old.keys() & new.keys())
    if not common:
        return {"samples": 0, "identical": 0, "max_position_diff_m": None,
                "max_heading_diff_rad": None, "before_first_gap": 0,
                "max_position_diff_before_gap_m": None,
                "max_resent_position_diff_m": resent_position_diff_m(old),
                "max_position_drift_between_gaps_m": None}
    pairs = [(t, a, b) for t in common for a, b in itertools.product(old[t], new[t])]
    at = np.searchsorted(np.array(common), [t for t, _, _ in pairs])
    a = np.array([p[1] for p in pairs], dtype=np.int64)
    b = np.array([p[2] for p in pairs], dtype=np.int64)
    position, heading, differs = (np.zeros(len(common)) for _ in range(3))
    np.maximum.at(position, at, np.hypot(a[:, 0] - b[:, 0], a[:, 1] - b[:, 1]) * POSITION_LSB_M)
    np.maximum.at(heading, at, np.abs(a[:, 2] - b[:, 2]) * HEADING_LSB_RAD)
    np.maximum.at(differs, at, (a != b).any(axis=1).astype(np.float64))
    ticks = EncoderTrack.of(log, log_accepted, BulkDecoder(contract.database())).tick
    gaps = np.flatnonzero(np.diff(ticks) > 1)
    first_gap = int(ticks[gaps[0]]) if len(gaps) else int(ticks[-1])  # last tick before it
    before = int(np.searchsorted(np.array(common), first_gap, side="right"))
    first = np.array([(old[t][0][0] - new[t][0][0], old[t][0][1] - new[t][0][1])
                      for t in common], dtype=np.int64)
    return {
        "samples": len(common),
        "identical": int(np.count_nonzero(differs == 0)),
        "max_position_diff_m": float(position.max()),
        "max_heading_diff_rad": float(heading.max()),
        "before_first_gap": before,
        "max_position_diff_before_gap_m": float(position[:before].max()) if before else None,
        "max_resent_position_diff_m": resent_position_diff_m(old),
        "max_position_drift_between_gaps_m": drift_between_gaps_m(
            np.array(common), first, ticks[gaps + 1]) if replayable(log, log_accepted) else None,
    }


def replayable(frames: FrameArrays, accepted: npt.NDArray[np.bool_]) -> bool:
    """True when the recording firmware took exactly the log's accepted encoder frames, each on
    its tick, as far as the log tells: no ODOM_STATUS summary reports TIME_LOST or
    MAILBOX_OVERFLOW (frames merged on board) and the host's E2E check refused no encoder frame
    (a late one the firmware may have taken). Else a drift between gaps is no departure."""
    encoders = frames.can_id == contract.database().get_message_by_name("WHEEL_ENCODERS").frame_id
    if (encoders & ~accepted).any():
        return False
    try:
        page = BulkDecoder(contract.database()).decode_page(frames, "ODOM_STATUS", 0)
    except DecodeError:
        return True
    masks = page["ERROR_MASK"][accepted[page["index"]]].astype(np.int64)
    return not (masks & (ErrorFlag.TIME_LOST | ErrorFlag.MAILBOX_OVERFLOW)).any()


def drift_between_gaps_m(
    common: npt.NDArray[np.int64], offset: npt.NDArray[np.int64], gap_ends: npt.NDArray[np.int64]
) -> float:
    """How far the logged and the replayed positions move apart between two gaps of the log's
    encoder sequence after its first (m; before it they are compared as they are): ``offset``
    (log - replay, raw LSB, at the ``common`` ticks) less its value at the first common tick of
    its segment (``gap_ends``: the first tick after each gap), less one LSB per axis. Across a
    gap the recording firmware may have had frames the log lacks, so the offset may jump there;
    between gaps both firmwares take the same frames from the same heading (exact everywhere),
    so one firmware's offset stays put: on the bus, rounded to the LSB, within one LSB per axis
    of it."""
    if len(common) == 0:
        return 0.0
    segment = np.searchsorted(gap_ends, common, side="right")
    first = np.r_[True, segment[1:] != segment[:-1]]  # a segment's first common tick
    anchor = offset[np.flatnonzero(first)][np.cumsum(first) - 1]
    moved = np.maximum(np.abs(offset - anchor) - 1, 0)[segment > 0]
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
    resent = vs_log.get("max_resent_position_diff_m")
    if resent is not None and resent > tolerance.position_m:
        reasons.append(f"the log's resent positions differ from its first at the same encoder "
                       f"frame by up to {resent * 1e3:.4f} mm "
                       f"(tolerance {tolerance.position_m * 1e3:.4g} mm)")
    heading = vs_log["max_heading_diff_rad"]
    if heading is not None and heading > tolerance.heading_rad:
        reasons.append(f"its heading differs from the log's by up to {heading * 1e3:.4f} mrad "
                       f"(tolerance {tolerance.heading_rad * 1e3:.4g} mrad)")
    return reasons
