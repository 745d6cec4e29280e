"""The firmware lives and stalls a lockstep replay reproduces (``host.judge.replay``'s plan),
and its comparison with the log life by life.

A lockstep replay used to run one firmware from the log's first encoder frame, one tick per
frame: a log whose firmware powered up after the recorder started, rebooted, or stalled (a
SIGSTOP, a debugger halt: TIME_LOST, MAILBOX_OVERFLOW, a re-prime) then departed from the replay
although the firmware was right, and the replay FAILed it (issue #11: 2660 mrad on a live log).
What the log tells, the replay now lives too:

* **a power-up or reboot**: where the judges find each firmware life (``reboots.split_lives``
  as ``replay_boots.boot_starts`` reads it for a receiver fresh at the reboot, and for the
  log's first life a summary at UPTIME 0, ``first_power_up``) the replayed firmware
  is reset (``FirmwareBoard.reboot``, its receive FIFO cleared) on the frame that life primed
  on, so each life runs from its own power-up; before the first power-up the board is off;
* **a stall**: where the firmware sent nothing for ``LOST_TIME_PERIODS`` ticks or more while the
  encoder frames went on (``firmware_silences``), the replayed firmware runs no tick; its bus
  keeps the frames and the board's FIFO-locked controller hands it the first few when it
  resumes and overruns the rest, as the recording board did (``sim.board``).

Each life is then compared with the log's on its own (``versus_log`` on both buses cut at the
life's first encoder frame). A life that departs only after a stall, the part before it
identical, is UNJUDGED from that stall (with the reason), not FAILed: which frames a real
controller's FIFO kept (its acceptance filter, frames of other nodes the log may lack) is more
than a log can tell; unless its poses after the stall, identical for a while after the FIFO
drained, show the replay reproduced it (``replay_stallkept``): then the departure after them is
the log's own and FAILs. A life that departs before any stall FAILs.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from odocan.firmware.clock import LOST_TIME_PERIODS
from odocan.firmware.errors import ErrorFlag
from odocan.host.io.logs import FrameArrays
from odocan.host.judge.analysis import Tolerance
from odocan.host.judge.bootnamed import named_start, pose_enc_rows, powerup_poses
from odocan.host.judge.gapseen import crc_holds
from odocan.host.judge.pagesent import pages_counted_from
from odocan.host.judge.powerup import holds_first_cycle
from odocan.host.judge.reboots import (
    encoder_count_pages,
    page_counted_start,
    summary_start,
)
from odocan.host.judge.replay_boots import boot_starts
from odocan.host.judge.replay_compare import departures, versus_log
from odocan.host.judge.replay_events import replayed_positions
from odocan.host.judge.replay_jumps import JumpModel
from odocan.host.judge.replay_late import status_pages_sent_at
from odocan.host.judge.replay_resume import stalls_resume_excess_m
from odocan.host.judge.replay_sent import bus_off_silences, new_error_bits, sent_times_s
from odocan.host.judge.replay_stallkept import kept_stall
from odocan.host.judge.replay_track import EncoderTrack
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e import check_frames
from odocan.sim import contract
from odocan.sim.board import TX_LATENCY_S

IntArray = npt.NDArray[np.int64]
FIRMWARE_NODE = "ODOM_MCU"  # the DBC's sender name of the firmware's frames
PRIME_CANDIDATES = 8  # frames before the first power-up's priming frame the fit tries too


@dataclass(frozen=True)
class LifePlan:
    """What the replay lives besides one frame per tick, in the log's encoder frame numbers
    (positions in ``EncoderTrack.index``) and ticks (``EncoderTrack.tick``)."""

    starts: list[int]  # encoder frame number each life starts on (the first: 0 or its power-up)
    powered: bool  # the first life starts at a power-up seen in the log (the board off before)
    halts: list[tuple[int, int]] = field(default_factory=list)  # [first, end) ticks halted
    # encoder frame number -> True: the board is reset after it is on the bus (its FIFO cleared
    # with it: the firmware booted in INIT a tick before the frame it primed on, the summary
    # before that frame), False: before (it primed in its first tick)
    resets: dict[int, bool] = field(default_factory=dict)
    # the first life's priming frame is known (``fit_first_prime``): compared from (0, 0, 0)
    # there, not re-anchored as a log cut mid-drive
    primed_known: bool = False
    # (log position, first halted tick): a frame of another node the halted board's receive
    # FIFO held (``replay_halts``), fed once the tick before that halt has run
    held: tuple[tuple[int, int], ...] = ()
    # [first, end) ticks of a bus-off (``bus_off_silences``): the board runs, hears nothing
    deaf: list[tuple[int, int]] = field(default_factory=list)

    @property
    def trivial(self) -> bool:
        """One firmware from the log's first frame, never halted: the replay as it always ran."""
        return len(self.starts) == 1 and not self.powered and not self.halts

    def primed_on(self, frame: int) -> LifePlan:
        """This plan with its first life (a power-up in the log) primed on encoder frame
        ``frame`` instead, known."""
        first = min(self.resets)
        after = self.resets[first] and frame > 0
        resets = {k: v for k, v in self.resets.items() if k != first}
        resets[frame - 1 if after else frame] = after
        return LifePlan([frame, *self.starts[1:]], self.powered, self.halts, resets, True,
                        self.held, self.deaf)

    def halted_ticks(self, track: EncoderTrack) -> set[int]:
        """The ticks the board runs none (before the first power-up, and each stall)."""
        first = min(self.resets, default=0)
        ticks = set(range(int(track.tick[first]))) if self.powered else set()
        for first, end in self.halts:
            ticks.update(range(first, end))
        return ticks


def plan_lives(frames: FrameArrays, accepted: npt.NDArray[np.bool_],
               track: EncoderTrack) -> LifePlan:
    """The log's firmware lives and stalls (module docstring)."""
    decoder = BulkDecoder(contract.database())
    first = first_power_up(frames, decoder, track)
    boots = ([] if first is None else [first]) + boot_starts(frames, decoder)
    resets: dict[int, bool] = {}
    starts = [0]
    for start, summary in boots:
        k = min(int(np.searchsorted(track.index, start)), len(track.index) - 1)
        if k == 0 and first is None:
            continue
        starts.append(k)
        after = summary < int(track.index[k]) and k > 0  # booted before the frame: INIT
        resets[k - 1 if after else k] = after
    starts = sorted(set(starts[1:] if first is not None else starts))
    silences = firmware_silences(frames, decoder, track)
    deaf = bus_off_silences(frames, decoder, track, silences)
    return LifePlan(starts, first is not None, [s for s in silences if s not in deaf], resets,
                    deaf=deaf)


def first_power_up(frames: FrameArrays, decoder: BulkDecoder,
                   track: EncoderTrack) -> tuple[int, int] | None:
    """The encoder frame (log position) the log's first firmware primed on, and its boot
    summary's position, when the log holds its power-up (its first summary whose CRC holds says
    UPTIME 0) after its first encoder frame, by the rules ``reboots.split_lives`` applies to a
    reboot; else None."""
    try:
        page = decoder.decode_page(frames, "ODOM_STATUS", 0)
        message = decoder.message("ODOM_STATUS")
    except DecodeError:
        return None
    good = page["index"][crc_holds(frames, decoder, page["index"])]
    if len(good) == 0 or "UPTIME" not in page:
        return None
    row = int(np.searchsorted(page["index"], good[0]))
    if int(page["UPTIME"][row]) != 0:
        return None
    choices = dict(message.get_signal_by_name("STATE").choices or {})
    state = str(choices.get(int(page["STATE"][row]), ""))
    position = int(good[0])
    where, ok, lost = encoder_count_pages(frames, decoder)  # each page where it was sent
    sent = status_pages_sent_at(frames, decoder, where)
    counted = page_counted_start(position, len(frames), (track.index, track.counter),
                                 (sent, ok, lost), sent=np.minimum(sent, pages_counted_from(
                                     frames, decoder, where, (track.index.astype(np.int64),
                                                              track.counter.astype(np.int64)))))
    if "COUNTER" in page and not holds_first_cycle(int(page["COUNTER"][row])):
        # not the boot summary (lost): the firmware powered up a cycle or more before it
        return None if counted is None or counted <= int(track.index[0]) else (counted, position)
    start = summary_start(position, 0, state, track.index)
    said = named_start(powerup_poses(frames, decoder),
                       (track.index.astype(np.int64), track.counter.astype(np.int64)), position,
                       float(frames.timestamp_s[position]), pose_enc_rows(frames, decoder))
    for found in (counted, None if said is None else said[0]):  # the pose's word last
        if found is not None and found > start:
            start = found
    return (start, position) if start > int(track.index[0]) else None


def firmware_silences(frames: FrameArrays, decoder: BulkDecoder,
                      track: EncoderTrack) -> list[tuple[int, int]]:
    """[first, end) ticks in which the firmware ran none: between two of its frames while the
    encoder frames went on, from the tick after the one that sent the first to the one that
    sent the second (its encoder frame the latest before it), ``LOST_TIME_PERIODS`` ticks or
    more. The frames' own gap only preselects (over ``LOST_TIME_PERIODS - 1`` periods): on a
    bit-timed bus a tick's frames leave up to a few ms after it, and a firmware halted 9 ticks
    (10 periods between its ticks, the board's ``HALT_AFTER_S``: its FIFO overran) sent its
    frames 108.5 ms apart; taken only over 11 periods, the replay ran every tick, departed by
    0.14 mm and FAILed the correct firmware (issue #11)."""
    ids = [m.frame_id for m in contract.database().messages if m.senders == [FIRMWARE_NODE]]
    sent_s = sent_times_s(frames, decoder, ids)  # a tick's frames delayed: its first's time
    period_s = contract.cycle_time_s("WHEEL_ENCODERS")
    halts = []
    for at in np.flatnonzero(np.diff(sent_s) > (LOST_TIME_PERIODS - 1) * period_s).tolist():
        last = int(np.searchsorted(track.timestamp_s, sent_s[at], "right")) - 1
        resumed = int(np.searchsorted(track.timestamp_s, sent_s[at + 1], "right")) - 1
        if last < 0 or resumed <= last:
            continue
        # each side counted on by bus time from the encoder frame before the firmware's frame:
        # the frames between may be refused (late, delayed: the host took none of them)
        first = int(track.tick[last]) + 1 + _periods_after(track, last, sent_s[at], period_s)
        end = int(track.tick[resumed]) + _periods_after(track, resumed, sent_s[at + 1], period_s)
        if end - first >= LOST_TIME_PERIODS:
            halts.append((first, end))
    return halts


def _periods_after(track: EncoderTrack, frame: int, sent_s: float, period_s: float) -> int:
    """Whole periods from the track's ``frame`` to the tick that sent the firmware's frame at
    ``sent_s`` (it leaves ``TX_LATENCY_S`` after its tick): kobuki random 404, 14 s,
    ``delay=0.25:30,reboot=6:0.3,stall=9:0.5``, the rebooted firmware's first frames came 3
    ticks after the last encoder frame the host took (those between were late), its boot was
    replayed 3 ticks short and the new firmware took frames the recording one never had."""
    behind_s = sent_s - TX_LATENCY_S - float(track.timestamp_s[frame])
    return max(0, int(np.floor(np.round(behind_s / period_s, 6))))


def judge_lives(log: FrameArrays, accepted: npt.NDArray[np.bool_], replayed: FrameArrays,
                replayed_accepted: npt.NDArray[np.bool_], track: EncoderTrack, plan: LifePlan,
                tolerance: Tolerance, jumps: JumpModel | None = None) -> list[dict[str, Any]]:
    """Each life compared with the log's on its own: ``onboard_vs_log`` (``versus_log``, its
    jumps across gaps held to ``jumps``), the stalls in it, and ``unjudged`` (why, from which
    stall: the part before it agrees) or None."""
    fed = replayed_positions(log, track.index, replayed)  # the log's frames on the replay's bus
    t0 = float(log.timestamp_s[0])
    bounds = [*plan.starts, len(track.index)]
    result = []
    for k, (first, end) in enumerate(itertools.pairwise(bounds)):
        span = _span(track, fed, first, end, len(log), len(replayed))
        stalls = [(a, b) for a, b in plan.halts if track.tick[first] < a < track.tick[end - 1]]
        rebooted = k > 0 or plan.primed_known  # its start known: from (0, 0, 0) there
        vs = versus_log(log.select(span[0]), accepted[span[0]], replayed.select(span[1]),
                        rebooted, jumps)
        if stalls and jumps is not None:  # the log's own resume: no FIFO content excuses it
            lost = new_error_bits(log, BulkDecoder(contract.database()), track, stalls)
            vs["max_resume_excess_m"] = stalls_resume_excess_m(
                log.select(span[0]), accepted[span[0]],
                [_positions(track, stall, span[0].start) for stall in stalls],
                [bool(bits & ErrorFlag.TIME_LOST) for bits in lost], jumps, tolerance.position_m)
        life: dict[str, Any] = {
            "life": k, "t_s": round(float(log.timestamp_s[track.index[first]]) - t0, 3),
            "from_power_up": rebooted or plan.powered,
            "stalls": [{"t_s": _tick_s(track, a, t0), "ticks": b - a} for a, b in stalls],
            "onboard_vs_log": vs, "unjudged": None}
        resumed = (vs.get("max_resume_excess_m") or 0.0) <= 0.0
        if stalls and resumed and (departures(vs, tolerance) or _raw_departs(vs, tolerance)):
            cut = int(np.searchsorted(track.tick, stalls[0][0]))
            pre = _span(track, fed, first, cut, len(log), len(replayed))
            before = versus_log(log.select(pre[0]), accepted[pre[0]], replayed.select(pre[1]),
                                rebooted, jumps)
            if not departures(before, tolerance):
                life["onboard_vs_log_before_stall"] = before
                kept = kept_stall(log.select(span[0]), accepted[span[0]],
                                  replayed.select(span[1]),
                                  [(a - int(track.tick[first]), b - int(track.tick[first]))
                                   for a, b in stalls])
                if kept is None:
                    life["unjudged"] = _stalled_reason(k, life)
                else:  # reproduced: the departure after it is the log's (replay_stallkept)
                    life["stall_kept"] = kept
                    vs["max_position_diff_after_kept_stall_m"] = kept["max_position_diff_m"]
        result.append(life)
    return result


def _span(track: EncoderTrack, fed: IntArray, first: int, end: int, n_log: int,
          n_replayed: int) -> tuple[slice, slice]:
    """The log's and the replayed bus's frames from encoder frame ``first`` up to ``end``."""
    log_end = int(track.index[end]) if end < len(track.index) else n_log
    replay_end = int(fed[end]) if end < len(fed) else n_replayed
    return (slice(int(track.index[first]), log_end),
            slice(int(fed[first]) if first < len(fed) else n_replayed, replay_end))


def _positions(track: EncoderTrack, stall: tuple[int, int], start: int) -> tuple[int, int]:
    """The positions, from the log's ``start``, of the encoder frames at or after a stall's
    first and end ticks."""
    at = np.minimum(np.searchsorted(track.tick, stall), len(track.tick) - 1)
    first, end = (int(track.index[k]) - start for k in at.tolist())
    return first, end


def _tick_s(track: EncoderTrack, tick: int, t0: float) -> float:
    """The log's time (from its first frame) of the encoder frame at or after ``tick``."""
    at = min(int(np.searchsorted(track.tick, tick)), len(track.tick) - 1)
    return round(float(track.timestamp_s[at]) - t0, 3)


def _raw_departs(vs: dict[str, Any], tolerance: Tolerance) -> bool:
    """The positions as they are (``max_position_diff_raw_m``) off the log's beyond tolerance,
    where the verdict's own figures may hold the offset's jump across a stall to metres (the
    recording firmware's merge there is unknown): pmir random 409, 10 s,
    ``delay=0.3:55,stall=4:0.3,dup=0.05``, replayed identical, with ODOM_POSE_X raised 10 mm
    from 4.5 s (the first common pose after the stall later) PASSed within a 1.49 m allowance.
    A life identical before its stall and 10 mm off after it is not judged PASS. Not across a
    hole of the log (``replay_compare.recorder_holes``): its firmware took frames the replay is
    not fed there, so its positions are off the replay's as they are (a correct firmware's, a
    recorder's 0.2 s lost: ``tests/test_replay_gap_drift.py``)."""
    raw = vs.get("max_position_diff_raw_m")
    return raw is not None and raw > tolerance.position_m and not vs.get("holes")


def _stalled_reason(k: int, life: dict[str, Any]) -> str:
    """Why life ``k`` is UNJUDGED after its first stall (module docstring)."""
    stall = life["stalls"][0]
    return (f"life {k} (from t={life['t_s']:.2f} s) after its firmware's stall at "
            f"t={stall['t_s']:.2f} s ({stall['ticks']} ticks): the replayed firmware, halted "
            "there as the log shows, departs from the log's after it while it agreed before "
            "(which frames the recording board's receive FIFO kept is more than the log tells)")


def fit_first_prime(frames: FrameArrays, accepted: npt.NDArray[np.bool_], track: EncoderTrack,
                    plan: LifePlan, tolerance: Tolerance,
                    replay: Callable[[FrameArrays, LifePlan], FrameArrays]) -> LifePlan:
    """The plan with the log's first power-up primed on the frame whose replay agrees with the
    log (``replay``: the replayed bus of a prefix of the log under a plan), known.

    ``first_power_up`` reads the frame from ODOM_STATUS stamps and its count page, which a
    recorder may have delayed: only ever too late (``primedrange``: the trial's mon.log, 4
    frames). So, like ``primedrange``, the life is tried from each of ``PRIME_CANDIDATES``
    frames before it too, the latest first, on the log up to its first stall or the next life:
    a correct firmware agrees from the frame it primed on, a wrong one from none (a frame's
    shift moves the pose by the robot's motion in it, unless it stood still, when no shift
    matters). From none: the latest whose poses pair with the log's, known, so the life FAILs
    (re-anchored it would absorb an offset: a firmware 1 m off from its power-up PASSed); the
    plan as it was only when none pairs (a stall before the first pose: no word on it)."""
    if not plan.powered:
        return plan
    cut = _first_life_end(track, plan, len(frames))
    head, head_accepted = frames.select(slice(0, cut)), accepted[:cut]
    head_track = EncoderTrack.of(head, head_accepted, BulkDecoder(contract.database()))
    start, paired, agreed = plan.starts[0], None, None
    best: tuple[int, LifePlan] | None = None
    for frame in range(start, max(start - PRIME_CANDIDATES, 0) - 1, -1):
        tried = plan.primed_on(frame)
        if frame >= len(head_track.index):
            continue
        replayed = replay(head, tried)
        _, replayed_accepted = check_frames(replayed)
        vs = judge_lives(head, head_accepted, replayed, replayed_accepted, head_track,
                         replace(tried, starts=[frame]), tolerance)[0]["onboard_vs_log"]
        if vs["samples"] and not departures(vs, tolerance):
            if _positions_agree(vs, tolerance) and (best is None or vs["samples"] > best[0]):
                best = (int(vs["samples"]), tried)  # the most poses paired: its phase too
            agreed = agreed or tried
        paired = paired or (tried if vs["samples"] else None)
    return best[1] if best is not None else agreed or (plan if paired is None else paired)


def _positions_agree(vs: dict[str, Any], tolerance: Tolerance) -> bool:
    """The positions of a fit's candidate agree with the log's as they are, every one (the raw
    difference): the verdict may judge none of them (``replay_compare.replayable`` False, the
    comparison then re-anchored or by drift), so a candidate whose headings agree is not enough.
    Taken on that alone, the first candidate tried, primed 3 frames late (0.04 s), was kept for
    ``delay=0.3:50`` (pmir, seed 20): its 125 poses all 0.9 mm off, none identical, and the replay
    then FAILed the correct firmware (ODOM_TWIST DISTANCE 0.942 mm off); the frame it primed on
    gave all 126 identical. Of those that agree, the one pairing the most poses: primed 2 frames
    late, before the robot moved, it agreed too, but in the other pose phase (77 paired)."""
    raw = vs.get("max_position_diff_raw_m")
    return raw is not None and raw <= tolerance.position_m


def _first_life_end(track: EncoderTrack, plan: LifePlan, n_log: int) -> int:
    """The log position where the first life's fit stops: its first stall or the next life."""
    ends = [n_log] + [int(track.index[k]) for k in plan.starts[1:2]]
    if plan.halts:
        at = int(np.searchsorted(track.tick, plan.halts[0][0]))
        ends.append(int(track.index[at]) if at < len(track.index) else n_log)
    return min(ends)
