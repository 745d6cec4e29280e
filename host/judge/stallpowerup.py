"""The log's power-up proven by a stall before the first pose (issue #11: "a PASS/OK must never
hide a wrong pose"), when the firmware's first count pages that ``host.judge.powerup`` reads are
lost or no longer reach the power-up (their ODOM_STATUS COUNTER wrapped past the halt).

The evidence is the firmware's own, as ``stalls.primed_first`` reads it for a reboot's life:

* the first ODOM_STATUS frame heard is of the firmware's first cycle (``powerup
  .holds_first_cycle``) and its first summary says UPTIME 0: the log holds its power-up;
* every summary it sent before the stall says INIT and it sent no pose half before it: it had
  primed on no encoder frame when it halted (a firmware primes in the tick that takes its
  first frame and says so in that tick's summary);
* then it was silent for ``SILENCE_CYCLES`` cycles or more while the encoder frames went on, on
  time, until its first sample (``stalls.first_after_stall``): the position ``lo`` of the
  first encoder frame after its last frame before the stall.

A stalled MCU's receive FIFO keeps the first frames after it halted (``sim/mcu.py``), so it
primed on the first frame it had not read: one of frames 0 .. ``lo`` (a frame on the bus in the
tick of its last summary may have come before or after its read; frames before its power-up it
never heard). The rule holds only when those frames all carry the same counts (the robot did
not move): then whichever one it primed on, its pose (0, 0, 0) is the reference's at frame 0,
exactly, and a firmware off from there FAILs. A moving robot there leaves it unproven (the
start fitted, the reason said: ``stall_power_up``)."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.powerup import holds_first_cycle, starts_at_power_up
from odocan.host.judge.primedon import FRAMES_KEY, candidates
from odocan.host.judge.primedrange import primed_range_event
from odocan.host.judge.samples import ENC_E2E_PAGE, Encoders, FloatArray, Poses
from odocan.host.judge.stalls import first_after_stall, silent_between
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.sim.robot import RobotProfile

UNPROVEN_KIND = "power_up_unproven"  # the report's event when the rule cannot prove it
INIT = "INIT"  # ODOM_STATUS STATE's name (the DBC's VAL_) of a firmware that primed on nothing
UNPROVEN = ("the firmware stalled before its first pose after its power-up (INIT at UPTIME 0) "
            "while the robot moved: the encoder frame it primed on is not known, so its first "
            "pose is not judged (the reference's start fitted)")


def stall_proves_power_up(frames: FrameArrays, accepted: npt.NDArray[np.bool_],
                          decoder: BulkDecoder, enc: Encoders, sent_s: FloatArray,
                          alive_s: FloatArray) -> bool:
    """The module docstring's rule on a whole log's first life (``sent_s``: its samples' bus
    times; ``alive_s``: its accepted ODOM_STATUS frames'): its power-up at encoder frame 0."""
    return stalled_power_up(frames, accepted, decoder, enc, sent_s, alive_s) is True


def stalled_power_up(frames: FrameArrays, accepted: npt.NDArray[np.bool_],
                     decoder: BulkDecoder, enc: Encoders, sent_s: FloatArray,
                     alive_s: FloatArray) -> bool | None:
    """``stall_proves_power_up``, None when the firmware stalled after its power-up but the
    robot moved over the frames it may have primed on (``stall_power_up``); False when the log
    shows no such stall."""
    lo = primed_by(frames, accepted, decoder, enc, sent_s, alive_s)
    return lo is not None and (unmoved(enc.left, enc.right, lo) or None)


def primed_by(frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder,
              enc: Encoders, sent_s: FloatArray, alive_s: FloatArray) -> int | None:
    """``lo`` of the module docstring: the firmware halted after its power-up before it primed
    and primed on one of encoder frames 0 .. ``lo``; None when the log shows no such stall."""
    halves = _pose_half_times(frames, accepted, decoder)
    if len(sent_s) == 0 or halves is None or not len(alive_s):
        return None
    first_s = float(np.min(sent_s))
    alive = np.sort(np.concatenate((alive_s, halves)))
    lo = first_after_stall(first_s, enc, alive)
    if lo is None:
        return None
    talked_s = float(alive[int(np.searchsorted(alive, first_s, side="left")) - 1])
    if np.any(halves <= talked_s) or not _primed_on_nothing(frames, accepted, decoder, talked_s):
        return None
    return lo


def stall_power_up(frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder,
                   enc: Encoders, sent_s: FloatArray,
                   alive_s: FloatArray) -> tuple[bool, list[dict[str, Any]]]:
    """``stall_proves_power_up`` and the report's events: a ``power_up_unproven`` one (at the
    first sample's bus time, ``UNPROVEN`` its detail) when ``stalled_power_up`` is None, the
    verdict's line says it (``host.report.summary.kept_unjudged``): never a silent PASS."""
    proven = stalled_power_up(frames, accepted, decoder, enc, sent_s, alive_s)
    if proven is not None:
        return proven, []
    return False, [{"kind": UNPROVEN_KIND, "t_s": float(np.min(sent_s)), "detail": UNPROVEN}]


def log_power_up(frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder,
                 onboard: Poses, enc: Encoders, times_s: tuple[FloatArray, FloatArray],
                 judged: tuple[RobotProfile, str]) -> tuple[bool, list[dict[str, Any]]]:
    """The power-up of the log's first life and the report's events (``times_s``: its samples'
    and its ODOM_STATUS frames' bus times, ``stall_power_up``'s; ``judged``: the robot and
    integrator): the firmware's count page (``powerup.starts_at_power_up``), else the stall's
    rule. When the firmware halted at power-up before it primed (``primed_by``), the page's
    tick bound (``powerup.heard_by_tick``) proves nothing: it takes one ODOM_STATUS cycle a
    period on the bus, while the halt held the page's tick seconds past the bound, so the
    frames on the bus by then are not those the firmware counted. Issue #11: frame 0 moved,
    the bound counted it, the firmware primed on frame 1 (its FIFO was drained at tick 0): the
    reference started a frame early and FAILed the correct firmware by 29.8 mm / 15.8 mrad.
    Then only an exact count (the frames before the page, or the pose before it) proves the
    power-up, else the stall's rule: frames 0 .. lo unmoved, or unproven, said, with each
    frame's start (``primedon``: the life judged from each); the count page's late priming
    too, judged from each frame it allows (``primedrange``). A firmware that primed, then
    halted before its first count page (``stalled_before_page``) sent that page a stall past
    the bound too: the bound is no evidence either (issue #11: reset with its FIFO cleared, one
    pose, halted 600 ticks; the bound's 11 frames from the log's first met ENC_E2E_OK 11 by
    chance, the reference started a frame early and FAILed the correct firmware by 5 mm)."""
    lo = primed_by(frames, accepted, decoder, enc, *times_s)
    if lo is None:
        if starts_at_power_up(frames, accepted, decoder, onboard, by_tick=not stalled_before_page(
                frames, accepted, decoder, enc, times_s[1])):
            return True, []
        return False, primed_range_event(  # its count page: primed on frame k or before
            frames, accepted, decoder, enc, float(np.min(times_s[0])), judged)
    if unmoved(enc.left, enc.right, lo) or starts_at_power_up(frames, accepted, decoder,
                                                               onboard, by_tick=False):
        return True, []
    return False, [{"kind": UNPROVEN_KIND, "t_s": float(np.min(times_s[0])), "detail": UNPROVEN,
                    FRAMES_KEY: candidates(enc, lo, *judged)}]


def unmoved(left: npt.NDArray[np.int64], right: npt.NDArray[np.int64], lo: int) -> bool:
    """Encoder frames 0 .. ``lo`` (their wire counts) all carry frame 0's counts."""
    if lo >= len(left):
        return False
    return bool(np.all(left[: lo + 1] == left[0]) and np.all(right[: lo + 1] == right[0]))


def _primed_on_nothing(frames: FrameArrays, accepted: npt.NDArray[np.bool_],
                       decoder: BulkDecoder, talked_s: float) -> bool:
    """The first ODOM_STATUS frame heard is of the first cycle, the first summary says UPTIME
    0, and every summary up to bus time ``talked_s`` (the stall's start) says INIT."""
    try:
        status = decoder.decode(frames, "ODOM_STATUS")
        summary = decoder.decode_page(frames, "ODOM_STATUS", 0)
        choices = dict(decoder.message("ODOM_STATUS").get_signal_by_name("STATE").choices or {})
    except (DecodeError, KeyError):
        return False
    if not {"COUNTER"} <= status.keys() or not {"UPTIME", "STATE"} <= summary.keys():
        return False
    counters = status["COUNTER"][accepted[status["index"]]]
    keep = accepted[summary["index"]] & (summary["timestamp_s"] <= talked_s)
    init = [code for code, name in choices.items() if str(name) == INIT]
    if not len(counters) or not holds_first_cycle(int(counters[0])) or not keep.any():
        return False
    return int(summary["UPTIME"][keep][0]) == 0 and bool(np.isin(summary["STATE"][keep],
                                                                 init).all())


def _pose_half_times(frames: FrameArrays, accepted: npt.NDArray[np.bool_],
                     decoder: BulkDecoder) -> FloatArray | None:
    """The bus times of the accepted ODOM_POSE_X and ODOM_POSE_Y frames (sorted); None when the
    DBC has neither."""
    times = []
    for name in ("ODOM_POSE_X", "ODOM_POSE_Y"):
        try:
            rows = decoder.decode(frames, name)
        except DecodeError:
            return None
        times.append(rows["timestamp_s"][accepted[rows["index"]]])
    return np.sort(np.concatenate(times))


def stalled_before_page(frames: FrameArrays, accepted: npt.NDArray[np.bool_],
                        decoder: BulkDecoder, enc: Encoders, alive_s: FloatArray) -> bool:
    """Whether the firmware (its accepted ODOM_STATUS frames' bus times ``alive_s``, its pose
    halves) was silent ``SILENCE_CYCLES`` cycles or more while the encoder frames went on
    before its first accepted page of WHEEL_ENCODERS E2E counts (``stalls.silent_between``)."""
    halves = _pose_half_times(frames, accepted, decoder)
    try:
        page = decoder.decode_page(frames, "ODOM_STATUS", ENC_E2E_PAGE)
    except DecodeError:
        return False
    paged = page["timestamp_s"][accepted[page["index"]]]
    if halves is None or not len(paged):
        return False
    alive = np.sort(np.concatenate((alive_s, halves)))
    return silent_between(alive[alive <= paged[0]], enc.timestamp_s, enc.cycle_s)
