"""A stall the firmware re-primed after, cut by a bare APPLY a few ticks after it resumed (issue
#11: "a FAIL must never blame a correct firmware"; ``host.judge.stallreprime``).

A firmware that re-primed at a stall says so on its next ODOM_STATUS summary (ERROR_MASK's
sticky COUNTER_RESET: ``nearthreshold.Resets.told``). An APPLY a few ticks after it resumed
cuts the log into a new life (``setposes``), so the stall's evidence falls on both sides of
the cut; judged on one side alone the correct firmware FAILed 56 of 64 drives
(``tests/test_reprime_apply.py``, ``test_reprime_sweep.py``):

- The life before the APPLY holds the clear summary before the stall and none after: its
  re-prime was not declared, its lone sample judged with the exact heading across the stall's
  left-out motion (2.4 to 8 rad). A set-pose or a config is no reboot: the summaries after the
  cut are the same firmware's, the bit it latched before still set (an APPLY releases the
  REASON, not the bit). So that life's word is read on (``later_word``) to the first summary
  made ``AFTER_PERIODS`` periods after its last frame, no further (a later latch is the next
  life's, judged there).
- An APPLY taken before the firmware's first fresh frame (in the tick after it drained its
  FIFO's backlog) lies between the pose it kept and the frame it re-primed on: the new life's
  first sample is the firmware's first after the silence, and names a backlog frame (ENC_COUNTER
  cannot resolve it: ``stalls.after_stalls`` leaves such a sample out within a life), paired
  with the frame the APPLY took effect after; its fitted reference then took the step the
  re-prime left out (one frame's turn off: 6.3 mrad, 12.6 on the spin; the distance 4.4 mm).
  That sample is left out here too (``backlog_first``); what the APPLY kept is judged by
  ``reprimekept`` against the frames the firmware can have integrated.

The streamed judge (its lives judged each on its own frames) refuses such a cut's life
(``STREAM``, ``backlog_in``: the CLI judges the log whole), as it refuses a declared re-prime.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.cutreprime import Backlog
from odocan.host.judge.nearthreshold import AFTER_PERIODS, SUMMARY_PAGE, Resets
from odocan.host.judge.reboots import Life
from odocan.host.judge.samples import FloatArray, IntArray, Poses, contract_cycle_s
from odocan.host.judge.stalls import alive_times, stalled_before
from odocan.host.protocol import busfacts
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e import check_frames

if TYPE_CHECKING:
    from odocan.host.judge.gapseen import Seen
    from odocan.host.protocol.dbcplan import DatabaseSpec

Word = tuple[FloatArray, IntArray]  # summaries' bus times and ERROR_MASKs
WINDOW_FRAMES = 512  # log frames the streamed judge reads each side of a cut (``backlog_in``)
STREAM = ("an APPLY, a set-pose's or a config's, cut the firmware's first pose after a stall "
          "off the life before it: the pose names a backlog frame")


@dataclass(frozen=True)
class CutEvidence:
    """What ``later_word`` and ``backlog_first`` read of the whole log, decoded once: the
    accepted summaries (log positions, bus times, ERROR_MASKs: none when the DBC has no
    ERROR_MASK), the accepted ODOM_POSE_Y (positions, bus times), the firmware's signs of life
    (bus times, sorted), the accepted encoder frames' bus times and their cycle."""

    summaries: tuple[IntArray, FloatArray, IntArray]
    poses: tuple[IntArray, FloatArray]
    alive_s: FloatArray
    enc_s: FloatArray
    cycle_s: float | None


def cut_evidence(frames: FrameArrays, db: DatabaseSpec, firmware_lives: list[Life],
                 lives: list[Life]) -> CutEvidence | None:
    """``CutEvidence`` of ``frames``, E2E checked afresh in each of the ``firmware_lives`` (a
    rebooted firmware's COUNTERs restart: ``analyze``'s own rule); None when none of the
    ``lives`` is a cut's (nothing to read across)."""
    if not any(_is_cut(life) for life in lives):
        return None
    accepted = np.zeros(len(frames), dtype=bool)
    for life in firmware_lives:
        accepted[life.index] = check_frames(frames.select(life.index), db)[1]
    return _evidence(frames, accepted, BulkDecoder(db))


def _evidence(frames: FrameArrays, accepted: npt.NDArray[np.bool_],
              decoder: BulkDecoder) -> CutEvidence:
    """``CutEvidence`` of ``frames`` whose E2E ``accepted`` are given."""
    try:
        page = decoder.decode_page(frames, "ODOM_STATUS", SUMMARY_PAGE)
    except (DecodeError, KeyError):
        page = {}
    at = np.asarray(page.get("index", np.zeros(0, dtype=np.int64)), dtype=np.int64)
    keep = accepted[at] if "ERROR_MASK" in page else np.zeros(len(at), dtype=bool)
    summaries = (at[keep], frames.timestamp_s[at[keep]],
                 np.asarray(page.get("ERROR_MASK", at), dtype=np.int64)[keep])
    pose_at = _accepted_index(frames, accepted, decoder, "ODOM_POSE_Y")
    pose_s = frames.timestamp_s[pose_at]
    return CutEvidence(summaries, (pose_at, pose_s),
                       np.sort(np.concatenate((alive_times(frames, accepted, decoder), pose_s))),
                       frames.timestamp_s[_accepted_index(frames, accepted, decoder,
                                                          "WHEEL_ENCODERS")],
                       contract_cycle_s(decoder, "WHEEL_ENCODERS"))


def _is_cut(life: Life) -> bool:
    """A set-pose's or a config's life: the same firmware as the life before."""
    return life.set_pose is not None or life.config is not None


def later_word(evidence: CutEvidence | None, lives: list[Life], k: int,
               timestamp_s: FloatArray) -> Word | None:
    """The summaries the same firmware sent after life ``k``'s last frame (``timestamp_s``:
    the log's bus times), up to the first made ``AFTER_PERIODS`` periods after it; None when
    the next life is a reboot's (another firmware's word) or none was."""
    if evidence is None or len(lives[k].index) == 0:
        return None
    end = int(lives[k].index[-1])
    reboot = next((j for j in range(k + 1, len(lives)) if not _is_cut(lives[j])), len(lives))
    if reboot == k + 1:
        return None
    limit = int(lives[reboot].index[0]) if reboot < len(lives) else len(timestamp_s)
    at, sent_s, mask = evidence.summaries
    after = (at > end) & (at < limit)
    sent_s, mask = sent_s[after], mask[after]
    made = np.flatnonzero(sent_s >= float(timestamp_s[end]) + AFTER_PERIODS * busfacts.ENC_CYCLE_S)
    if len(made) == 0:
        return None
    return sent_s[: int(made[0]) + 1], mask[: int(made[0]) + 1]


def heard_later(seen: Seen, word: Word | None) -> Seen:
    """``seen`` with its COUNTER_RESET word read on by the ``later_word`` summaries."""
    resets = seen.resets
    if word is None or (len(resets.sent_s) and float(word[0][0]) <= float(resets.sent_s[-1])):
        return seen
    return replace(seen, resets=Resets(
        np.concatenate((resets.sent_s, word[0])), np.concatenate((resets.mask, word[1])),
        resets.long_gaps, resets.cycle_s, resets.holes))


def backlog_first(evidence: CutEvidence | None, life: Life) -> bool:
    """Whether a cut's life (``_is_cut``) has as its first sample the firmware's first after a
    stall (``stalls.stalled_before`` on the whole log's frames: silent ``SILENCE_CYCLES``
    cycles or more while the encoder frames went on, on time)."""
    if evidence is None or not _is_cut(life):
        return False
    pose_at, pose_s = evidence.poses
    first_s = pose_s[np.isin(pose_at, life.index)]
    return len(first_s) > 0 and stalled_before(
        float(first_s[0]), evidence.enc_s, evidence.cycle_s, evidence.alive_s)


def _accepted_index(frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder,
                    name: str) -> IntArray:
    """The log positions of the accepted frames of ``name``."""
    rows = decoder.decode(frames, name)
    index: IntArray = rows["index"][accepted[rows["index"]]]
    return index


def without_first(onboard: Poses, sent_s: FloatArray) -> tuple[Poses, FloatArray]:
    """The samples but the first sent (``backlog_first``), unless it is the only one (a lone
    sample at the APPLY's frame is its kept pose, the fitted start's own)."""
    if len(sent_s) < 2:
        return onboard, sent_s
    keep = np.arange(len(sent_s)) != int(np.argmin(sent_s))
    return Poses(onboard.enc[keep], onboard.x_m[keep], onboard.y_m[keep],
                 onboard.heading_rad[keep], onboard.heading_raw[keep]), sent_s[keep]


def backlog_in(window: FrameArrays, db: DatabaseSpec, start: int) -> bool:
    """``backlog_first`` of the cut's life whose frames start at ``start`` in ``window`` (the
    log's frames around it, ``WINDOW_FRAMES`` each side: the streamed judge's). No sign of
    the firmware's life in the window before its first pose there: the silence is at least
    the window's (its first frame's time taken for its last word: refused rather than missed)."""
    evidence = _evidence(window, check_frames(window, db)[1], BulkDecoder(db))
    if len(window) and len(evidence.poses[1]):
        evidence = replace(evidence, alive_s=np.concatenate((window.timestamp_s[:1],
                                                             evidence.alive_s)))
    life = Life(np.arange(start, len(window), dtype=np.int64), False, set_pose=True)
    return backlog_first(evidence, life)


def backlog_of(evidence: CutEvidence | None, lives: list[Life], k: int) -> Backlog | None:
    """``cutreprime.Backlog`` of life ``k`` when ``acrosscut.backlog_first`` says so, else None."""
    if not backlog_first(evidence, lives[k]):
        return None
    return Backlog(earlier_word(evidence, lives, k))


def earlier_word(evidence: CutEvidence | None, lives: list[Life], k: int) -> Word | None:
    """The summaries the same firmware sent before life ``k``'s first frame, back to its
    firmware life's start (a reboot's life, or the log's first: another firmware before it);
    None when none was."""
    if evidence is None or k == 0 or len(lives[k].index) == 0:
        return None
    j = k - 1
    while j > 0 and (lives[j].set_pose is not None or lives[j].config is not None):
        j -= 1
    lo = int(lives[j].index[0]) if len(lives[j].index) else 0
    at, sent_s, mask = evidence.summaries
    before = (at >= lo) & (at < int(lives[k].index[0]))
    return (sent_s[before], mask[before]) if before.any() else None
