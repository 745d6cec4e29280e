"""The firmware's stalls and holds in a log (``host.judge.analysis`` module docstring, step 3):
samples sent after the firmware was silent while the encoder frames went on, and poses it held on
one frame, after which it took the frames it missed as one step, so the reference's position is
placed again there, within the bound of ``host.judge.breaks``."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.gapfill import crc_holds
from odocan.host.judge.samples import (
    SILENCE_CYCLES,
    Encoders,
    FloatArray,
    IntArray,
    PoseHalves,
    Poses,
    queued_frames,
)
from odocan.host.protocol.decode import BulkDecoder


def after_stalls(
    onboard: Poses, sent_s: FloatArray, enc: Encoders, pose_sent_s: FloatArray | None = None,
    alive_s: FloatArray | None = None, halves: PoseHalves | None = None,
) -> tuple[Poses, IntArray]:
    """Samples sent after the firmware was silent for ``SILENCE_CYCLES`` encoder cycles or more
    (no ODOM_POSE_Y at all: ``pose_sent_s``, every one's bus time, also those that name the
    previous sample's frame again, e.g. queued ones the bus let out late) while the log holds
    the encoder frames of that time, which came on time (``frames_on_time``; a stalled MCU,
    firmware/ecu.py TIME_LOST): the first names a frame from before the silence
    (its backlog), which ENC_COUNTER cannot resolve, so it is left out; and the firmware took the
    frames it missed as one step, which a fine reference cannot follow on a curve, so the
    reference's position restarts (a segment, like a gap) at the encoder frame after the last
    sample before the silence. The same restart where the firmware kept talking but held its
    pose (``_frozen``). The first sample too when the firmware was silent before it after its
    other frames (``alive_s``: e.g. its ODOM_STATUS while INIT, ``first_after_stall``): the
    restart is then at the frame after the first it could have primed on (a lone sample so
    placed is kept: ``_lone_break``). ``halves``: the pose frames and the frames they name, a
    hold's evidence (``named_again``, ``frozen_breaks``; None: no evidence asked).
    Returns the samples kept and those encoder frames (sorted)."""
    if enc.cycle_s is None or len(sent_s) == 0:
        return onboard, np.zeros(0, dtype=np.int64)
    if len(sent_s) == 1:
        return onboard, _lone_break(float(sent_s[0]), enc, pose_sent_s, alive_s)
    order = np.argsort(sent_s, kind="stable")  # samples are sorted by encoder frame, not sent
    sent = sent_s[order]
    # Silent while the encoder frames went on, on time (a log that lacks both is a recorder's
    # gap; a bus that held both back let the frames out in a burst), anywhere between two
    # samples (``inner_silences``: between any two poses the firmware sent, queued ones naming
    # the same frame included); only a sample right after its silence (the firmware's first
    # pose after it) may name a backlog frame: that one is left out.
    quiet_from, first_after = inner_silences(sent, pose_sent_s, enc)
    # A sample let out in a burst (queued_frames) was not silent: the bus held it back.
    queued = queued_frames(sent, enc.cycle_s)
    after = np.flatnonzero(np.isfinite(quiet_from) & ~queued[1:]) + 1
    keep = np.ones(len(sent_s), dtype=bool)
    keep[order[after[first_after[after - 1]]]] = False
    primed = stalled_first(sent_s, enc, alive_s, pose_sent_s)
    if primed is not None:
        keep[order[0]] = False
    kept = Poses(onboard.enc[keep], onboard.x_m[keep], onboard.y_m[keep],
                 onboard.heading_rad[keep], onboard.heading_raw[keep])
    queued_by_sample = np.zeros(len(sent_s), dtype=bool)
    queued_by_sample[order] = queued
    evidence = None if halves is None else hold_evidence(
        named_again(halves, len(enc.seq), enc.timestamp_s)[kept.enc], sent_s[keep],
        sent if pose_sent_s is None else pose_sent_s, enc.cycle_s)
    frozen = _frozen(kept, enc, queued_by_sample[keep], evidence)
    restarts = [last_named_before(onboard.enc[order[after - 1]], quiet_from[after - 1], enc,
                                  halves) + 1, frozen]
    if primed is not None:
        restarts.append(np.array([primed + 1], dtype=np.int64))
    breaks = np.sort(np.concatenate(restarts))
    first = np.ones(len(breaks), dtype=bool)  # np.unique by hand: its plain form imports
    first[1:] = breaks[1:] != breaks[:-1]  # numpy.ma (10 ms of start-up) for nothing
    return kept, breaks[first].astype(np.int64)


def stalled_first(sent_s: FloatArray, enc: Encoders, alive_s: FloatArray | None,
                  pose_sent_s: FloatArray | None) -> int | None:
    """``after_stalls``' stall before the first sample (its arguments'): the position in
    ``enc`` of the first frame the firmware could have primed on (``first_after_stall``, its
    pose halves alive too), None without one."""
    if enc.cycle_s is None or len(sent_s) < 2:
        return None
    return first_after_stall(float(np.min(sent_s)), enc, _alive(alive_s, pose_sent_s))


def first_placement(sent_s: FloatArray, enc: Encoders, alive_s: FloatArray | None,
                    pose_sent_s: FloatArray | None, kept: Poses) -> tuple[int, int] | None:
    """The placement after a stall before the first sample (``after_stalls``' arguments and
    the samples it ``kept``): the positions in ``enc`` of the first frame the firmware could
    have primed on and of the first sample kept, where the position is placed again; None
    without such a stall. The frames between are the placement's, no loss span's
    (``losses.placement_accounted``)."""
    primed = stalled_first(sent_s, enc, alive_s, pose_sent_s)
    if primed is None or len(kept.enc) == 0:
        return None
    return primed, int(np.min(kept.enc))


def _lone_break(sent_s: float, enc: Encoders, pose_sent_s: FloatArray | None,
                alive_s: FloatArray | None) -> IntArray:
    """A life's lone sample (e.g. a set-pose cut it one tick after): after a stall from before
    it (``first_after_stall``), the reference's position restarts after the frame the firmware
    could first have primed on and is placed at that sample within the merge allowance; kept,
    not left out, for there is no later one to place on (before: compared with the fine path
    from the power-up, a correct firmware FAILed at 1.27 mm,
    ``tests/test_set_pose_after_first_stall.py``)."""
    primed = first_after_stall(sent_s, enc, _alive(alive_s, pose_sent_s))
    return np.array([] if primed is None else [primed + 1], dtype=np.int64)


def _alive(alive_s: FloatArray | None, pose_sent_s: FloatArray | None) -> FloatArray | None:
    """The firmware's signs of life: its pose halves too (one that made no sample)."""
    if alive_s is None or pose_sent_s is None:
        return alive_s
    return np.sort(np.concatenate((alive_s, pose_sent_s)))


def first_after_stall(sent_s: float, enc: Encoders, alive_s: FloatArray | None) -> int | None:
    """A stall before the first sample (issue #11): the firmware sent other frames (``alive_s``,
    bus times, sorted: its ODOM_STATUS while INIT), then nothing for ``SILENCE_CYCLES`` cycles
    or more while the encoder frames went on, on time, until its first sample (``sent_s``). A
    stalled MCU then primes on the first frame its FIFO kept and takes the frames it missed as
    one step: the position in ``enc`` of the first frame it could have primed on (the first
    after its last other frame), else None (no such silence, or no frame before it to tell)."""
    if enc.cycle_s is None or alive_s is None or len(enc.timestamp_s) == 0:
        return None
    k = int(np.searchsorted(alive_s, sent_s, side="left")) - 1
    if k < 0:
        return None
    talked = float(alive_s[k])
    lo = np.searchsorted(enc.timestamp_s, [talked]).astype(np.int64)
    hi = np.searchsorted(enc.timestamp_s, [sent_s]).astype(np.int64)
    quiet = silent(np.array([sent_s - talked]), frames_on_time(enc, lo, hi), enc.cycle_s)
    return int(lo[0]) if bool(quiet[0]) and int(lo[0]) < len(enc.timestamp_s) else None


def stalled_before(sent_s: float, enc_t_s: FloatArray, cycle_s: float | None,
                   alive_s: FloatArray) -> bool:
    """``first_after_stall`` on the encoder frames' bus times alone (all it reads of them):
    whether a firmware's first sample, sent at ``sent_s``, came after a stall since its last
    frame of ``alive_s`` (a reboot's life, ``reboots.stalled_first`` and ``stream_lives``)."""
    n = np.arange(len(enc_t_s), dtype=np.int64)
    enc = Encoders(n, n, n, n, n, enc_t_s, cycle_s)
    return first_after_stall(sent_s, enc, alive_s) is not None


def silent_between(alive_s: FloatArray, enc_t_s: FloatArray, cycle_s: float | None) -> bool:
    """Whether a firmware alive at the bus times ``alive_s`` (sorted: its ODOM_STATUS and pose
    frames) was silent ``SILENCE_CYCLES`` cycles or more between two of them while the encoder
    frames (bus times ``enc_t_s``) went on, on time (``silent``): it stalled there, whether
    before its first pose or after it (``reboots.stalled_first``: a stall before its first
    count page, which then misses the frames its FIFO overran)."""
    if cycle_s is None or len(alive_s) < 2:
        return False
    n = np.arange(len(enc_t_s), dtype=np.int64)
    enc = Encoders(n, n, n, n, n, enc_t_s, cycle_s)
    lo = np.searchsorted(enc_t_s, alive_s[:-1]).astype(np.int64)
    hi = np.searchsorted(enc_t_s, alive_s[1:]).astype(np.int64)
    return bool(np.any(silent(np.diff(alive_s), frames_on_time(enc, lo, hi), cycle_s)))


def primed_first(sent_s: float, enc: Encoders, alive_s: FloatArray,
                 pose_sent_s: FloatArray) -> bool:
    """A rebooted firmware's life (its frames from its boot summary) whose first sample, sent
    at ``sent_s``, came after a stall from before any encoder frame of the life
    (``first_after_stall`` names the life's first: the summary said INIT): a stalled MCU's
    receive FIFO kept the first frames after it halted, so it primed on that one, its power-up
    (0, 0, 0) there, though its first page of E2E counts misses the frames the FIFO overran
    (``powerup.saw_only_the_log`` cannot hold). A firmware that primed elsewhere is off the
    exact heading from there: it FAILs, never PASSes by this rule."""
    if not np.isfinite(sent_s):
        return False
    alive = np.sort(np.concatenate((alive_s, pose_sent_s)))
    return first_after_stall(sent_s, enc, alive) == 0


def alive_times(frames: FrameArrays, accepted: npt.NDArray[np.bool_],
                decoder: BulkDecoder) -> FloatArray:
    """The bus times of the firmware's accepted ODOM_STATUS frames (``first_after_stall``)."""
    rows = decoder.decode(frames, "ODOM_STATUS")
    times: FloatArray = rows["timestamp_s"][accepted[rows["index"]]]
    return times


def pose_sent_times(frames: FrameArrays, accepted: npt.NDArray[np.bool_],
                    decoder: BulkDecoder) -> FloatArray:
    """The bus times of the firmware's ODOM_POSE_Y frames (the silence rules' ``pose_sent_s``):
    those accepted and those the host's E2E refused whose CRC holds (issue #11). A frame a
    ``delay`` fault reordered is refused as a wrong sequence (a later one came first), yet the
    firmware sent it: counted as silence, 140 ms of poses refused on ``delay=0.3:55`` (seed
    703) made a stall the firmware never had, whose placement absorbed a pose 10 mm off."""
    rows = decoder.select(frames, "ODOM_POSE_Y")
    sent = accepted[rows] | crc_holds(frames, decoder, rows, "ODOM_POSE_Y")
    times: FloatArray = np.sort(frames.timestamp_s[rows[sent]]).astype(np.float64)
    return times


def signs_of_life(frames: FrameArrays, accepted: npt.NDArray[np.bool_],
                  decoder: BulkDecoder) -> tuple[FloatArray, FloatArray]:
    """(``pose_sent_times``, ``alive_times``) of a log."""
    return pose_sent_times(frames, accepted, decoder), alive_times(frames, accepted, decoder)


def frames_on_time(enc: Encoders, lo: IntArray, hi: IntArray) -> IntArray:
    """How many of the encoder frames ``lo[k]`` .. ``hi[k]`` - 1 (positions in ``enc``) came on
    time: not ``queued_frames`` (a busy bus let them out in a burst). A firmware that missed
    frames which came on time was silent or held (a stall); frames the bus held back came all
    at once, and a firmware that drains them one by one in its next tick missed none of them
    (its mailbox may drop some: ENC_E2E_LOST counts those, ``losses.firmware_losses``)."""
    if enc.cycle_s is None:
        return np.asarray(hi - lo, dtype=np.int64)
    on_time = ~queued_frames(enc.timestamp_s, enc.cycle_s)
    before = np.concatenate(([0], np.cumsum(on_time, dtype=np.int64)))
    counted: IntArray = before[hi] - before[lo]
    return counted


def _frozen(onboard: Poses, enc: Encoders, queued: npt.NDArray[np.bool_],
            evidence: npt.NDArray[np.bool_] | None = None) -> IntArray:
    """Encoder frames after a sample whose next sample names a frame ``SILENCE_CYCLES`` or more
    periods later while the log holds ``SILENCE_CYCLES`` frames between that came on time
    (``frames_on_time``): the firmware held its pose on one frame (it kept naming it) and then
    took the frames since as one step, as after a stall."""
    heard = frames_on_time(enc, onboard.enc[:-1] + 1, onboard.enc[1:] + 1)
    return frozen_breaks(onboard.enc, enc.seq[onboard.enc], queued, heard, evidence)


def frozen_breaks(sample_enc: IntArray, sample_seq: IntArray,
                  queued: npt.NDArray[np.bool_] | None = None,
                  heard: IntArray | None = None,
                  evidence: npt.NDArray[np.bool_] | None = None) -> IntArray:
    """``_frozen`` of consecutive samples (their encoder frames in the log and sequence
    numbers, in encoder order; ``queued``: which came in a burst, None: none did; ``heard``: the
    frames on time between each two, None: every frame between, as when none came in a burst;
    ``evidence``: per two consecutive samples, ``hold_evidence``'s, None: every pair has it).

    A hold needs evidence (issue #11, rule 5): a firmware that held its pose kept naming the
    frame it held on, so a pose frame after the sample named that frame again; or it was silent
    between the two on the bus (a stall whose burst of queued poses the silence rule does not
    count, ``tests/test_apply_after_stall.py``). Two samples far
    apart in the log are no evidence alone: under a ``delay`` fault the host refuses most pose
    and encoder frames (reordered), the samples left are sparse, and a hold invented between two
    of them placed the reference again at the later one, absorbing a pose 10 mm off (seed 703,
    ``delay=0.5:100``: 12 of 73 poses judged, a tamper from 2.0 s PASSed)."""
    on_time = np.diff(sample_enc) if heard is None else heard
    held = (np.diff(sample_seq) >= SILENCE_CYCLES) & (on_time >= SILENCE_CYCLES)
    if evidence is not None:
        held &= evidence
    if queued is not None:
        held &= ~queued[1:]  # a queued sample was made long before it was sent: not evidence
    frozen: IntArray = sample_enc[:-1][held] + 1
    return frozen


def named_again(halves: PoseHalves, frames: int, enc_t_s: FloatArray | None = None
                ) -> npt.NDArray[np.bool_]:
    """Per encoder frame (of ``frames``), whether two accepted pose frames of one kind or more
    named it (``halves``: ``samples.pose_halves``): a hold's evidence (``frozen_breaks``).
    With ``enc_t_s`` (the accepted encoder frames' bus times) the second must come after the
    next accepted frame did: a firmware that names a frame again before the next one it takes
    came held nothing (issue #11: under ``delay`` its E2E window refuses the on-time frames for
    up to 16 periods, and it names its last frame meanwhile, as the host's E2E check says it
    must; read as a hold, the frames after it earned a stall's allowance, 11.7 mm, which
    absorbed a pose 10 mm off: kobuki, seed 2, ``delay=0.5:100``)."""
    again = np.zeros(frames, dtype=bool)
    for named, rows in ((halves.ex, halves.px), (halves.ey, halves.py)):
        ok = named >= 0
        if enc_t_s is not None and frames:
            nxt = np.minimum(named + 1, frames - 1)
            came = (named + 1 < frames) & (rows["timestamp_s"] >= enc_t_s[nxt])
            firsts = np.bincount(named[ok & ~came], minlength=frames)[:frames]
            # named again after the next frame came: a naming after it beyond the first naming
            late = np.bincount(named[ok & came], minlength=frames)[:frames]
            again |= (late >= 1) & (firsts + late >= 2)
            continue
        counts = np.bincount(named[ok], minlength=frames)
        again |= counts[:frames] >= 2
    return again


def hold_evidence(again: npt.NDArray[np.bool_], sent_s: FloatArray, pose_sent_s: FloatArray,
                  cycle_s: float | None) -> npt.NDArray[np.bool_]:
    """``frozen_breaks``' evidence per two consecutive samples (in encoder order): the first's
    frame named again (``again``, per sample: ``named_again``), or no pose frame sent
    (``pose_sent_s``, sorted) for ``SILENCE_CYCLES`` - 0.5 cycles or more between the two
    samples' send times (``sent_s``)."""
    if cycle_s is None or len(sent_s) < 2:
        return np.asarray(again[:-1], dtype=bool)
    return again[:-1] | quiet_between(sent_s[:-1], sent_s[1:], pose_sent_s, cycle_s)


def quiet_between(t0_s: FloatArray, t1_s: FloatArray, pose_sent_s: FloatArray,
                  cycle_s: float) -> npt.NDArray[np.bool_]:
    """Per pair (t0, t1): ``quiet_in`` of the silences of ``pose_sent_s`` (sorted): two
    consecutive times ``SILENCE_CYCLES`` - 0.5 cycles apart or more (as ``silent``)."""
    gap = np.flatnonzero(np.diff(pose_sent_s) >= (SILENCE_CYCLES - 0.5) * cycle_s)
    return quiet_in(t0_s, t1_s, pose_sent_s[gap], pose_sent_s[gap + 1], cycle_s)


def quiet_in(t0_s: FloatArray, t1_s: FloatArray, starts_s: FloatArray, ends_s: FloatArray,
             cycle_s: float) -> npt.NDArray[np.bool_]:
    """Per pair (t0, t1): whether the silences (``starts_s`` .. ``ends_s``, sorted) within it
    leave less than ``SILENCE_CYCLES`` cycles of it talked: the firmware that talked longer
    between two samples named the frames of that time (its poses the host could not pair are
    sparse samples, no hold; 75 ms without a pose in 1.5 s of ``delay=0.5:100`` held none)."""
    if len(starts_s) == 0:
        return np.zeros(len(t0_s), dtype=bool)
    quiet_sum = np.concatenate(([0.0], np.cumsum(ends_s - starts_s)))
    j0 = np.searchsorted(starts_s, t0_s, side="left")
    j1 = np.maximum(np.searchsorted(ends_s, t1_s, side="right"), j0)
    quiet: npt.NDArray[np.bool_] = (j1 > j0) & (
        quiet_sum[j1] - quiet_sum[j0] >= (t1_s - t0_s) - SILENCE_CYCLES * cycle_s)
    return quiet


def silent(
    quiet_s: FloatArray, heard: IntArray, cycle_s: float
) -> npt.NDArray[np.bool_]:
    """``after_stalls``' silence before each next sample (``quiet_s``: seconds since the
    firmware last sent a pose, ``heard``: encoder frames logged on time meanwhile): at least half
    a cycle short of ``SILENCE_CYCLES`` (samples come in whole send periods, and time stamps
    summed in float must not decide: 79.999... ms is 80 ms) while the encoder frames went on."""
    quiet: npt.NDArray[np.bool_] = (
        (quiet_s >= (SILENCE_CYCLES - 0.5) * cycle_s) & (heard >= SILENCE_CYCLES - 1)
    )
    return quiet


def inner_silences(sent: FloatArray, pose_sent_s: FloatArray | None,
                   enc: Encoders) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
    """Per two consecutive samples (``sent``: their send times, sorted), the bus time the
    firmware's first silence between them (``silent``: no ODOM_POSE_Y, ``pose_sent_s``, while
    the encoder frames went on, on time) began (inf: none), and whether a silence ended right
    at the second sample (it is the firmware's first pose after it). Issue #11: under ``delay`` and
    ``dup`` the host pairs few of the poses a firmware sends after a stall, so the next sample
    may come long after its first poses; read only right before that sample, a 6 s halt was
    no stall (pmir, seed 2, ``delay=0.3:55,dup=0.1,stall=4:6``: the reference integrated the
    halt the firmware re-primed across and FAILed it by 252.9 mm)."""
    out = np.full(max(len(sent) - 1, 0), np.inf)
    ends = np.zeros(len(out), dtype=bool)
    if enc.cycle_s is None or len(sent) < 2:
        return out, ends
    talk = sent if pose_sent_s is None else np.sort(np.concatenate((sent, pose_sent_s)))
    t_a, t_b = talk[:-1], talk[1:]
    heard = frames_on_time(enc, np.searchsorted(enc.timestamp_s, t_a),
                           np.searchsorted(enc.timestamp_s, t_b))
    quiet = np.flatnonzero(silent(t_b - t_a, heard, enc.cycle_s))
    k = np.searchsorted(sent, t_a[quiet], side="right") - 1  # the sample before each silence
    inside = (k >= 0) & (k < len(sent) - 1)
    for pair, start in zip(k[inside][::-1].tolist(), t_a[quiet][inside][::-1].tolist(),
                           strict=True):
        out[pair] = start  # reversed: the first silence of a pair is written last
    last = k[inside]
    ends[last[t_b[quiet][inside] == sent[last + 1]]] = True
    return out, ends


def last_named_before(sample_enc: IntArray, quiet_s: FloatArray, enc: Encoders,
                      halves: PoseHalves | None) -> IntArray:
    """Per stall, the last encoder frame (a position in ``enc``) the firmware named before its
    silence began at ``quiet_s``: its sample's (``sample_enc``) or a later one a pose half
    named whose bus time is at or before that start (issue #11: sparse samples under ``delay``
    put the last sample 0.3 s before the halt; the stall's break there left the re-prime's
    frames ``stallreprime`` chooses from 30 frames short)."""
    out = np.asarray(sample_enc, dtype=np.int64).copy()
    if halves is None or len(enc.timestamp_s) == 0:
        return out
    named = np.concatenate((halves.ex, halves.ey))
    ok = named >= 0
    named = named[ok]
    named_t = enc.timestamp_s[named]
    for i, t in enumerate(quiet_s.tolist()):
        if math.isfinite(t):
            before = named[named_t <= t]
            if len(before):
                out[i] = max(int(out[i]), int(np.max(before)))
    return out
