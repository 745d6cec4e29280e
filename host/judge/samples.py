"""The inputs of the analysis, from the frames: E2E-accepted rows decoded with the DBC, the
encoder sequence, the exact alignment of the pose and truth frames to the encoder frames they name,
and whether the log starts at the firmware's power-up (``host.judge.analysis`` module docstring,
steps 1 to 3; the power-up rule of step 4 is ``host.judge.powerup``)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays, TimeOrder
from odocan.host.judge import floodnames
from odocan.host.judge.latehalves import Half, halves_together
from odocan.host.judge.latenames import sent_places
from odocan.host.judge.queuednames import queued_names
from odocan.host.judge.reference import INTEGRATORS, Geometry
from odocan.host.judge.refusedenc import Refused, refused_encoders
from odocan.host.judge.resendalias import may_alias
from odocan.host.judge.senderseq import QUEUED_GAP_CYCLES as QUEUED_GAP_CYCLES
from odocan.host.judge.senderseq import pose_skips
from odocan.host.judge.senderseq import queued_frames as queued_frames
from odocan.host.judge.senderseq import sender_seq as sender_seq
from odocan.host.protocol import busfacts
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK as MASK
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e import crc8h2f_p02, e2e_messages
from odocan.sim.exceptions import OdocanError

HALF_LAP = ENC_COUNTER_LAP // 2  # 8: ENC_COUNTER names a frame -8..+7 on

# One LSB of the pose signals, from the DBC's scales (the single source of truth): X, Y 0.1 mm,
# HEADING a 16-bit binary angle (2 pi / 65536 rad).
_POSE_X = default_plan().get_message_by_name("ODOM_POSE_X")
POSITION_LSB_M = float(_POSE_X.get_signal_by_name("X").scale)
HEADING_LSB_RAD = float(_POSE_X.get_signal_by_name("HEADING").scale)
WIRE_COUNTER_BITS = busfacts.ENC_WIRE_COUNTER_BITS  # WHEEL_ENCODERS: each count's low 24 bits
SILENCE_CYCLES = 8  # pose frames this many encoder cycles apart: the firmware was stalled
START_FIT_SAMPLES = 256  # on-board samples used to place the reference start (5 s at 50 Hz)
ENC_E2E_PAGE = busfacts.ENC_E2E_PAGE  # ODOM_STATUS page with the WHEEL_ENCODERS E2E counts
REQUIRED = ("WHEEL_ENCODERS", "ODOM_POSE_X", "ODOM_POSE_Y")

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


class AnalysisError(OdocanError):
    """The frames cannot be analysed: DBC and log do not match, nothing to compare, ..."""



@dataclass(frozen=True)
class Encoders:
    """The accepted WHEEL_ENCODERS frames, in bus order."""

    index: IntArray  # position in the frames
    counter: IntArray  # E2E COUNTER
    seq: IntArray  # the sender's sequence number (COUNTER unwrapped), strictly increasing
    left: IntArray  # LEFT_COUNT (wire, 24 bits)
    right: IntArray
    timestamp_s: FloatArray
    cycle_s: float | None  # the DBC cycle time
    twinned: npt.NDArray[np.bool_] | None = None  # ``twinned_encoder_frames``; None: none
    twins: tuple[IntArray, IntArray, IntArray] | None = None  # ``encoder_twins``; None: none
    uptime: IntArray | None = None  # CTRL_UPTIME (0: not reported); None: the DBC has none
    # a flood's ambiguous names an ODOM_POSE_X's HEADING resolved (``floodnames.follow``)
    renamed: tuple[IntArray, IntArray, IntArray, FloatArray] | None = None


@dataclass(frozen=True)
class Poses:
    """Samples of a pose (on-board or truth), one per encoder frame, sorted by it."""

    enc: IntArray  # index into Encoders
    x_m: FloatArray
    y_m: FloatArray
    heading_rad: FloatArray  # on-board: TURNS * 2 pi + HEADING; truth: HEADING (wrapped)
    heading_raw: IntArray  # HEADING, BAM16



# --- inputs ---------------------------------------------------------------------------------


def require_messages(decoder: BulkDecoder) -> None:
    """The DBC must define the messages the analysis reads."""
    missing = []
    for name in REQUIRED:
        try:
            decoder.message(name)
        except DecodeError:
            missing.append(name)
    if missing:
        raise AnalysisError(f"the DBC does not define {', '.join(missing)}: not the odocan DBC?")


def accepted_rows(
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
    if keep.all():  # the usual case: the decoded arrays are fresh, no copy of them needed
        return decoded
    return {key: value[keep] for key, value in decoded.items()}


def no_summary(frames: FrameArrays | TimeOrder) -> AnalysisError:
    """The error of a log without an accepted ODOM_STATUS summary: that its times run back
    when most do (a reversed log's summaries all fail their E2E sequence), else to give the
    integrator."""
    if isinstance(frames, TimeOrder):
        order = frames
    else:
        order = TimeOrder()
        order.feed(frames)
    said = order.out_of_order()
    return AnalysisError(f"{said}: no ODOM_STATUS summary read in order to tell the integrator"
                         if said else
                         "no ODOM_STATUS summary in the log to tell the integrator: give it")


def pick_integrator(
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
        raise no_summary(frames)
    choices: dict[Any, Any] = dict(signal.choices or {})
    name = str(choices.get(int(values[-1]), "")).lower()
    if name not in INTEGRATORS:
        raise AnalysisError(f"ODOM_STATUS reports an unknown integrator ({int(values[-1])})")
    return name, "ODOM_STATUS"


def encoder_frames(
    frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder
) -> Encoders:
    """The accepted encoder frames and their sender sequence numbers: COUNTER steps, widened by
    16 where the time stamps say that many more periods passed, unless the frame after the gap
    came in a burst (``queued_frames``); and which have a twin (``twinned_encoder_frames``)."""
    rows = decoder.decode(frames, "WHEEL_ENCODERS")
    keep = accepted[rows["index"]]
    twins = encoder_twins(frames, rows, keep, decoder)
    twinned = np.isin(np.arange(int(np.count_nonzero(keep))), twins[0])
    enc = accepted_rows(frames, accepted, decoder, "WHEEL_ENCODERS")
    counter = enc["COUNTER"].astype(np.int64)
    cycle_s = contract_cycle_s(decoder, "WHEEL_ENCODERS")
    return Encoders(
        index=enc["index"], counter=counter,
        seq=sender_seq(counter, enc["timestamp_s"], cycle_s, _holes(frames, accepted, decoder,
                                                                   enc["index"])),
        left=enc["LEFT_COUNT"].astype(np.int64), right=enc["RIGHT_COUNT"].astype(np.int64),
        timestamp_s=enc["timestamp_s"], cycle_s=cycle_s,
        twinned=twinned if twinned.any() else None, twins=twins if twinned.any() else None,
        uptime=enc["CTRL_UPTIME"].astype(np.int64) if "CTRL_UPTIME" in enc else None)


def _holes(frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder,
           enc_index: IntArray) -> npt.NDArray[np.bool_]:
    """``senderseq.pose_skips`` of the encoder frames at ``enc_index``, from the accepted
    ODOM_POSE_X frames."""
    poses = accepted_rows(frames, accepted, decoder, "ODOM_POSE_X")
    return pose_skips(enc_index.astype(np.int64), poses["index"].astype(np.int64),
                      poses["COUNTER"].astype(np.int64))


def twinned_encoder_frames(
    frames: FrameArrays, rows: dict[str, np.ndarray], keep: npt.NDArray[np.bool_],
    decoder: BulkDecoder,
) -> npt.NDArray[np.bool_]:
    """Which accepted WHEEL_ENCODERS frames (``rows``: every one decoded, ``keep``: those E2E
    accepted) have a twin: a later frame of the same COUNTER before the next accepted one, less
    than half a COUNTER cycle (8 periods) after it, its CRC right but its counts different (E2E
    refused it as REPEATED; 16 lost frames later the same COUNTER is the sender's next cycle).
    A forger's frame (random payloads pass Profile 2's CRC about once in 256) or a second
    sender's; either may have come first. The firmware took whichever reached its mailbox first
    and was kept, and a full mailbox drops frames the bus log holds, so a pose naming that
    COUNTER cannot be told to belong to either: ``match_encoder`` names none (the pose is left
    out, not guessed one period off). An exact repetition (the same counts) is no twin."""
    return np.isin(np.arange(int(np.count_nonzero(keep))), encoder_twins(frames, rows, keep,
                                                                         decoder)[0])


def encoder_twins(
    frames: FrameArrays, rows: dict[str, np.ndarray], keep: npt.NDArray[np.bool_],
    decoder: BulkDecoder,
) -> tuple[IntArray, IntArray, IntArray]:
    """``twinned_encoder_frames``' twins, one element each: the accepted frame it twins (its
    index among the accepted ones) and its LEFT_COUNT, RIGHT_COUNT (``host.judge.twins``)."""
    none = np.zeros(0, dtype=np.int64)
    refused = np.flatnonzero(~keep)
    if len(refused) == 0 or not keep.any():
        return none, none, none
    kept = np.flatnonzero(keep)
    before = np.searchsorted(kept, refused) - 1  # the latest accepted frame before each
    refused, before = refused[before >= 0], before[before >= 0]
    prev = kept[before]
    same = (rows["COUNTER"][refused] == rows["COUNTER"][prev]) & (
        (rows["LEFT_COUNT"][refused] != rows["LEFT_COUNT"][prev])
        | (rows["RIGHT_COUNT"][refused] != rows["RIGHT_COUNT"][prev]))
    cycle_s = contract_cycle_s(decoder, "WHEEL_ENCODERS")
    if cycle_s is not None:  # 16 periods on, the same COUNTER is the sender's next cycle
        same &= rows["timestamp_s"][refused] - rows["timestamp_s"][prev] < 8 * cycle_s
    config = next(m for m in e2e_messages(decoder.db).values() if m.name == "WHEEL_ENCODERS")
    if not same.any() or config.data_ids is None:
        return none, none, none
    data = frames.data[rows["index"][refused[same]]]
    ids = np.asarray(config.data_ids, dtype=np.uint8)[rows["COUNTER"][refused[same]] & MASK]
    crc_right = crc8h2f_p02(data, ids) == data[:, 0]
    twin = refused[same][crc_right]
    return (before[same][crc_right].astype(np.int64), rows["LEFT_COUNT"][twin].astype(np.int64),
            rows["RIGHT_COUNT"][twin].astype(np.int64))


def contract_cycle_s(decoder: BulkDecoder, name: str) -> float | None:
    """A message's cycle time in seconds (None when it has none)."""
    cycle_ms = decoder.message(name).cycle_time
    return cycle_ms / 1000.0 if cycle_ms else None


def match_encoder(
    enc: Encoders, index: IntArray, enc_counter: IntArray, timestamp_s: FloatArray,
    own_counter: IntArray | None = None, *, causal: bool = True,
) -> IntArray:
    """For frames at ``index`` (sent at ``timestamp_s``) naming ``enc_counter``: the encoder
    frame named (index into ``enc``), -1 where it is not among the accepted encoder frames
    before the naming frame (host.judge.analysis docstring, step 3). The latest accepted encoder
    frame must be less than 8 cycles older than the naming frame: else the frame named (-8..+7
    from it) cannot be told from one 16 cycles away (after a gap of 16 frames, E2E refuses the
    next as a repetition). ``own_counter``: the naming frames' E2E COUNTER (one message), to
    carry a repeated ENC_COUNTER over consecutive sends (``_held``). ``causal`` False: the named
    frame may come later in the log (SIM_TRUTH: the simulator names its own sample, whenever the
    encoder frame reaches the bus)."""
    result = np.full(len(index), -1, dtype=np.int64)
    has, target = named_targets(enc, index, enc_counter, timestamp_s)
    target = target[has]
    found = np.minimum(np.searchsorted(enc.seq, target), len(enc.seq) - 1)
    before = (enc.index[found] < index[has]) | (not causal)  # not integrated before it came
    result[np.flatnonzero(has)] = np.where((enc.seq[found] == target) & before, found, -1)
    if own_counter is not None and enc.cycle_s is not None:
        result = _held(result, enc_counter, own_counter, timestamp_s, enc.cycle_s)
        result = lapped_out(result, enc.seq, latest_seq(enc, index))
        result = queued_names(result, enc, index, enc_counter, own_counter, timestamp_s)
    if enc.twinned is not None:  # which of a frame and its twin the firmware had is unknown
        result[(result >= 0) & enc.twinned[np.maximum(result, 0)]] = -1
    if enc.renamed is not None and enc.cycle_s is not None and causal:
        result = floodnames.follow(result, enc_counter, timestamp_s, enc.renamed, enc.cycle_s)
    return result


def named_targets(
    enc: Encoders, index: IntArray, enc_counter: IntArray, timestamp_s: FloatArray
) -> tuple[npt.NDArray[np.bool_], IntArray]:
    """``match_encoder``'s first step: which frames have a latest accepted encoder frame before
    them less than 8 cycles older, and the sequence number each names from it (``enc`` not
    empty)."""
    latest = np.searchsorted(enc.index, index) - 1
    has = latest >= 0
    last = np.maximum(latest, 0)
    if enc.cycle_s is not None:
        has &= timestamp_s - enc.timestamp_s[last] < HALF_LAP * enc.cycle_s
    step = ((enc_counter - enc.counter[last] + HALF_LAP) & MASK) - HALF_LAP
    target: IntArray = enc.seq[last] + step
    return has, target


def _held(
    named: IntArray, enc_counter: IntArray, own_counter: IntArray, timestamp_s: FloatArray,
    cycle_s: float,
) -> IntArray:
    """``named`` with each frame that repeats the ENC_COUNTER of its sender's previous send
    (own COUNTER + 1, less than ``SILENCE_CYCLES`` cycles later) naming what that one named
    (host.judge.analysis docstring, step 3), along runs of such repeats."""
    if len(named) < 2:
        return named
    repeat = np.concatenate(([False], (
        (np.diff(enc_counter) == 0)
        & ((np.diff(own_counter) & MASK) == 1)
        & (np.diff(timestamp_s) < SILENCE_CYCLES * cycle_s)
    )))
    run_start = np.maximum.accumulate(np.where(repeat, 0, np.arange(len(named))))
    held: IntArray = named[run_start]
    return held


def latest_seq(enc: Encoders, index: IntArray) -> IntArray:
    """Per naming frame at log position ``index``: the sender sequence number of the latest
    accepted encoder frame before it (a very low number where none is)."""
    latest = np.searchsorted(enc.index, index) - 1
    none = np.iinfo(np.int64).min // 2
    seq: IntArray = np.where(latest >= 0, enc.seq[np.maximum(latest, 0)], none)
    return seq


def lapped_out(named: IntArray, seq: IntArray, latest: IntArray) -> IntArray:
    """``named`` (after ``_held``), with -1 where the frame named lies a COUNTER lap or more
    behind the latest accepted encoder frame before the naming frame (``latest``: its sender
    sequence number; ``seq``: the encoder frames' numbers): a repeated ENC_COUNTER carried
    over a burst of 16 or more encoder frames (a sender that paused and then sent its backlog
    back to back, a babbler's queue let out). Less than ``SILENCE_CYCLES`` cycles after the
    send before, the repeat may be a resend (the firmware had not drained the burst yet) or
    name a frame of the burst of the same COUNTER a lap on or more (it had): the name is left
    out, not guessed. Carried as a resend, the twist the firmware made over the burst's
    merged steps was judged in the window before the silence (a sim SIGSTOPped 3 s then
    flooding: 0.05 m/s against 0.46, a FAIL of a correct firmware). A name resolved from the
    latest frame lies within half a lap of it: never left out."""
    lapped = (named >= 0) & (latest - seq[np.maximum(named, 0)] >= ENC_COUNTER_LAP)
    kept: IntArray = np.where(lapped, -1, named)
    return kept


def _first_per_encoder(enc_idx: IntArray) -> tuple[IntArray, IntArray]:
    """Encoder frames named (sorted, unique) and the first position naming each: where the
    named frames never go back (the usual case: a sender names them in bus order), where each
    value first appears, without ``np.unique``'s sort."""
    named = np.flatnonzero(enc_idx >= 0)
    values = enc_idx[named]
    if len(values) > 1 and not bool(np.all(values[1:] >= values[:-1])):
        uniq, first = np.unique(values, return_index=True)
        return uniq, named[first]
    new = np.empty(len(values), dtype=bool)
    new[:1] = True
    np.not_equal(values[1:], values[:-1], out=new[1:])
    return values[new], named[new]


@dataclass(frozen=True)
class PoseHalves:
    """Every accepted ODOM_POSE_X and ODOM_POSE_Y frame (decoded rows) and the encoder frame
    each names (``match_encoder``; -1: none): the samples' source, and the resent poses'
    (``host.judge.resent``: every pose frame is judged, not only the first naming a frame)."""

    px: dict[str, np.ndarray]
    py: dict[str, np.ndarray]
    ex: IntArray
    ey: IntArray
    ax: npt.NDArray[np.bool_] | None = None  # per half: may name another frame (resendalias)
    ay: npt.NDArray[np.bool_] | None = None
    refused: Refused | None = None  # the encoder frames E2E refused, CRC right (aheadnamed)


def pose_halves(
    frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder, enc: Encoders
) -> PoseHalves:
    """The accepted pose frames and the encoder frame each names (a frame held back on the
    bus: from where it was sent, ``latenames``)."""
    px = accepted_rows(frames, accepted, decoder, "ODOM_POSE_X")
    py = accepted_rows(frames, accepted, decoder, "ODOM_POSE_Y")
    x, y = (_late_half(frames, decoder, name, rows)
            for name, rows in (("ODOM_POSE_X", px), ("ODOM_POSE_Y", py)))
    halves_together(x, y)  # one pose's halves named at one place
    ex = match_encoder(enc, x.place, x.enc_counter, x.sent_s, x.counter)
    ey = match_encoder(enc, y.place, y.enc_counter, y.sent_s, y.counter)
    return PoseHalves(px, py, ex, ey, may_alias(frames, decoder, enc, px["index"], ex),
                      may_alias(frames, decoder, enc, py["index"], ey),
                      refused_encoders(frames, accepted, decoder))


def _late_half(frames: FrameArrays, decoder: BulkDecoder, name: str,
               rows: dict[str, np.ndarray]) -> Half:
    """One pose message's accepted frames where ``latenames`` names each (``Half``)."""
    index = rows["index"].astype(np.int64)
    stamp_s = rows["timestamp_s"].astype(np.float64)
    enc_counter = rows["ENC_COUNTER"].astype(np.int64)
    place, _, sent_s = sent_places(frames, decoder, name, index, stamp_s, enc_counter)
    return Half(index, stamp_s, place.astype(np.int64).copy(), sent_s.astype(np.float64).copy(),
                rows["COUNTER"].astype(np.int64), enc_counter)


def flood_named(
    frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder, enc: Encoders,
    robot: tuple[Geometry, int],
) -> tuple[Encoders, PoseHalves]:
    """``pose_halves``, with each ODOM_POSE_X name a flood makes ambiguous resolved by its
    HEADING (``floodnames``; ``robot``: geometry, counter bits) and ``enc`` carrying those
    renames (``Encoders.renamed``): every frame sent with it (its Y half, the twist) follows
    in ``match_encoder``."""
    halves = pose_halves(frames, accepted, decoder, enc)
    px, plain = halves.px, halves.ex
    ex = floodnames.resolve_x(plain, enc.seq, enc.timestamp_s,
                              floodnames.cumulative_counts(enc.left, enc.right, robot[1]),
                              px["HEADING"].astype(np.int64), enc.cycle_s, robot[0])
    changed = np.flatnonzero(ex != plain)
    if len(changed) == 0:
        return enc, halves
    enc = replace(enc, renamed=(plain[changed], ex[changed],
                                px["ENC_COUNTER"][changed].astype(np.int64),
                                px["timestamp_s"][changed].astype(np.float64)))
    return enc, pose_halves(frames, accepted, decoder, enc)


def onboard_samples(
    frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder, enc: Encoders,
    halves: PoseHalves | None = None,
) -> tuple[Poses, int, FloatArray]:
    """On-board samples (X and Y frames of one encoder frame, the first of each); the poses
    left unmatched; and when each sample's ODOM_POSE_Y was sent (s). ``halves``: the frames'
    ``pose_halves`` when the caller has them already."""
    h = halves or pose_halves(frames, accepted, decoder, enc)
    px, py, ex, ey = h.px, h.py, h.ex, h.ey
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
    poses = Poses(
        enc=both.astype(np.int64),
        x_m=px["X"][sx] * POSITION_LSB_M,
        y_m=py["Y"][sy] * POSITION_LSB_M,
        heading_rad=turns * 2 * math.pi + heading_raw * HEADING_LSB_RAD,
        heading_raw=heading_raw,
    )
    return poses, unmatched, py["timestamp_s"][sy].astype(np.float64)


def truth_samples(
    frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder, enc: Encoders
) -> Poses:
    """Truth samples (X, Y and HEADING parts naming one encoder frame); empty without SIM_TRUTH."""
    try:
        parts = [decoder.decode_page(frames, "SIM_TRUTH", part) for part in (0, 1, 2)]
    except DecodeError:
        parts = []
    if not parts or any(len(p["index"]) == 0 for p in parts):
        return empty_poses()
    found = []
    for p in parts:
        keep = accepted[p["index"]]
        named = match_encoder(
            enc, p["index"][keep], p["ENC_COUNTER"][keep], p["timestamp_s"][keep], causal=False
        )
        uniq, first = _first_per_encoder(named)
        found.append((uniq, np.flatnonzero(keep)[first]))
    common = np.intersect1d(  # each part's frames named are sorted and unique already
        np.intersect1d(found[0][0], found[1][0], assume_unique=True), found[2][0],
        assume_unique=True,
    )
    pick = [f[1][np.searchsorted(f[0], common)] for f in found]
    heading_raw = parts[2]["HEADING"][pick[2]].astype(np.int64)
    return Poses(
        enc=common.astype(np.int64),
        x_m=parts[0]["X"][pick[0]] * POSITION_LSB_M,
        y_m=parts[1]["Y"][pick[1]] * POSITION_LSB_M,
        heading_rad=heading_raw.astype(np.float64) * HEADING_LSB_RAD,
        heading_raw=heading_raw,
    )


def empty_poses() -> Poses:
    empty_f, empty_i = np.zeros(0), np.zeros(0, dtype=np.int64)
    return Poses(empty_i, empty_f, empty_f, empty_f, empty_i)


def wrap_pi(angle: FloatArray) -> FloatArray:
    """Wrap to (-pi, pi], the one convention (``odocan.sim.truth.wrap_angle`` for arrays)."""
    wrapped: FloatArray = math.pi - (math.pi - angle) % (2 * math.pi)
    return wrapped
