"""Encoder-frame refusals the capture's timing cannot decide, settled from the firmware's own
evidence on the bus (issue #11: a live capture on a loaded machine FAILed a correct firmware).

A starved recorder (candump or the monitor on a loaded host) holds the frames it hears for up
to a few periods and stamps them in a burst, bus order kept: the stamps of two WHEEL_ENCODERS
frames no longer say how many of the firmware's ticks passed between them, and the host's model
of the firmware's E2E window (``e2e_periods.receive_periods``, which trusts stamps to
``CAPTURE_TOLERANCE_CYCLES``) refused frames the firmware took (a pose naming one was paired
with nothing, the reference split there) or took frames it refused.

Three readings of the stamps per pair of frames: the strict one (``receive_periods``), one
where the first frame's stamp may be up to ``CAPTURE_HOLD_CYCLES`` late (the window wider) and
one where the second's may (narrower). Where the three give one verdict, the timing decides.
Where they differ, the firmware's poses do:

* **taken**: an ODOM_POSE_X or _Y frame's ENC_COUNTER names the encoder frame the firmware
  integrated last before it sent the pose. Where the firmware moved on since the previous send
  of that message heard (a later one: ``e2e_sends``, at most ``NEAR_FRAMES`` encoder frames
  before), the named frame came after that send (less ``RACE_FRAMES``): it is the one frame
  of that COUNTER there, else no proof. A send naming the ENC_COUNTER of that send names what
  it named, unless another frame of that COUNTER came since (after a lock-out the firmware
  can move on by 16 frames in one send period: a frame 15 on, then the next).
* **skipped**: a frame on the bus before that previous send (so in the firmware's mailbox
  before this pose's tick) and after the frame this pose names was refused.

Both read the previous send's place on the bus as the time it was sent: a pose frame held back
on the bus (a ``delay`` fault) is no bound. One heard after a frame of its message sent later
(``heard_in_order``) is known late: the encoder frames heard before the time it was sent bound
instead (``sent_times``; issue #11, rule 5: on kobuki, seed 703,
``delay=0.5:150``, two ODOM_POSE_X sent at 0.361 and 0.421 s, both heard 150 ms late, made the
on-time WHEEL_ENCODERS COUNTER 7 at 0.55 s "taken", named by the second, which named the 7 at
0.39 s; the firmware had refused it, its window 0 after the late 8, and the reference, which
integrated it, was 209 mm / 183 mrad off a correct firmware).

Neither: the strict reading stands (its verdict is exact on a capture whose stamps are the
bus's, e.g. the lockstep rig's logs, where a firmware locked out by a late frame refuses the
frames on time after it).

The evidence also decides where the three readings agree but it speaks otherwise: the host's
last frame is then not the firmware's (a jittered stamp widened the host's window by a period in
a lock-out, and it took a frame the firmware refused: every later verdict of the lock-out was
against the wrong COUNTER). A frame proven skipped is refused, unless the readings' one window
takes it after a frame the firmware's check took last, or every window takes it and its counts
from there are beyond the robot's bound (``e2e_bound``): then its plausibility bound refused it
(``_bound_skip``); a frame proven taken that every window refuses takes back the host's frames
since the firmware's last (``e2e_retract``).

The status codes are ``host.protocol.e2e``'s (``_STATUS`` order: ok, oksomelost, repeated,
wrong_sequence, crc_error).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK, POSE_PERIOD_S
from odocan.host.protocol.e2e_bound import Beyond, by_counts, exact
from odocan.host.protocol.e2e_crosslate import crossed_late_of
from odocan.host.protocol.e2e_cycles import new_cycles
from odocan.host.protocol.e2e_implausible import Readings, by_stamps
from odocan.host.protocol.e2e_periods import (
    COUNTER_MODULO,
    RECEIVE_LAG_CYCLES,
    receive_periods,
)
from odocan.host.protocol.e2e_retract import firmware_last
from odocan.host.protocol.e2e_sends import later_sends
from odocan.host.protocol.e2e_windows import Windows

# How late a starved recorder may stamp a frame, in periods: held 1..4 periods (the trial's
# lateness reached +3.9), plus the stamp jitter of ``CAPTURE_TOLERANCE_CYCLES``.
CAPTURE_HOLD_CYCLES = 4.5
EVIDENCE_MESSAGES = ("ODOM_POSE_X", "ODOM_POSE_Y")
S_OK, S_LOST, S_REPEATED, S_WRONG, S_CRC = range(5)
# Encoder frames at most between two sends of a pose message for the second's ENC_COUNTER to
# name a frame found unambiguously (16 would allow a name 16 frames off; 2 of margin for a
# frame on the bus before a send that the firmware drained after it).
NEAR_FRAMES = 14
RACE_FRAMES = 2  # frames before a send that the firmware may have drained only after it
LATE_CYCLES = 1.5  # a frame heard this many send periods after its COUNTER's send: held back
HALF_PERIOD = 0.5  # a run's silence and a frame's lead agree within this (periods)
SILENCE_CYCLES = 1.5  # the recorder heard nothing (a bus is never that quiet in a drive)
BURST_S = 40e-6  # then stamped what it held this close (closer than a bus delivers frames)
ALIKE_S = 0.5e-6  # but not at once: frames of one instant (the rig's, float noise included)
IntArray = npt.NDArray[np.int64]


@dataclass(frozen=True)
class Evidence:
    """Encoder frames (indices into one message's frames) the firmware's poses prove it took
    or skipped; ``beyond``: a step (frame, frame, periods) beyond its bound (``e2e_bound``)."""

    taken: frozenset[int]
    skipped: frozenset[int]
    beyond: Beyond | None = None


def narrow_periods(dt_s: npt.NDArray[np.float64], step: IntArray, cycle_s: float,
                   hold_cycles: float = CAPTURE_HOLD_CYCLES) -> IntArray:
    """``receive_periods`` with the second frame's stamp taken late by capture (up to
    ``hold_cycles``): a second frame that looks late adds only the sender's step."""
    x = dt_s / cycle_s
    s = step + COUNTER_MODULO * np.floor((x - step + COUNTER_MODULO // 2) / COUNTER_MODULO)
    e = x - s
    np.copyto(e, np.maximum(e - hold_cycles, 0.0), where=e > 0)
    late = np.maximum(np.ceil(np.abs(e) - RECEIVE_LAG_CYCLES), 0.0)
    periods = np.maximum(s + np.sign(e) * late, 0.0)
    result: IntArray = periods.astype(np.int64)
    return result


def readings(timestamp_s: npt.NDArray[np.float64], counter: IntArray,
             crc_ok: npt.NDArray[np.bool_], cycle_s: float,
             strict: IntArray) -> tuple[IntArray, IntArray]:
    """The wide and narrow readings' periods of each frame (``strict``: ``frame_periods``'),
    differing from it only between two frames with a right CRC."""
    wide, narrow = strict.copy(), strict.copy()
    if len(timestamp_s) > 1:
        both = np.flatnonzero(crc_ok[1:] & crc_ok[:-1]) + 1
        dt = timestamp_s[both] - timestamp_s[both - 1]
        step = (counter[both] - counter[both - 1]) & (COUNTER_MODULO - 1)
        wide[both] = receive_periods(dt, step, cycle_s, CAPTURE_HOLD_CYCLES)
        narrow[both] = narrow_periods(dt, step, cycle_s)
    return wide, narrow


def evidence_frames(frames: FrameArrays, of_message: list[npt.NDArray[np.intp]],
                    messages: list[tuple[str, int]],
                    crc_ok: npt.NDArray[np.bool_]) -> list[npt.NDArray[np.intp]]:
    """The bus positions of each ``EVIDENCE_MESSAGES`` message's frames of its DLC with a right
    CRC (``of_message``: each message's positions; ``messages``: their names and DLCs)."""
    found = []
    for (name, length), at in zip(messages, of_message, strict=True):
        if name in EVIDENCE_MESSAGES:
            at = at[frames.dlc[at] == length]
            found.append(at[crc_ok[at]])
    return found


def pose_evidence(frames: FrameArrays, enc_pos: npt.NDArray[np.intp],
                  enc_counter: IntArray, enc_crc_ok: npt.NDArray[np.bool_],
                  poses: list[npt.NDArray[np.intp]]) -> Evidence:
    """What the pose frames ``poses`` (per message, bus positions of those with a right CRC)
    prove of the encoder frames at ``enc_pos`` (module docstring)."""
    good = np.flatnonzero(enc_crc_ok)
    taken: set[int] = set()
    skipped: set[int] = set()
    for at, late in zip(poses, crossed_late_of(frames, poses), strict=True):
        if len(at) < 2:
            continue
        counter = (frames.data[at, 1] & ENC_COUNTER_MASK).astype(np.int64)
        ordered, _, unread = send_readings(frames.timestamp_s[at], counter, POSE_PERIOD_S)
        # no proof: held back a lap's half or more, or read in order yet behind the other's sends
        keep = ~(np.asarray(unread, dtype=bool) | (late & np.asarray(ordered, dtype=bool)))
        at, counter = at[keep], counter[keep]
        named = (frames.data[at, 1] >> 4).astype(np.int64)
        before = np.searchsorted(enc_pos[good], at)  # good encoder frames before each pose
        since = _sent_places(frames.timestamp_s[at], counter, before,
                             frames.timestamp_s[enc_pos[good]])
        found: int | None = None  # the place in ``good`` of the frame the last send named
        later = later_sends(frames.timestamp_s[at], counter, POSE_PERIOD_S)  # on cadence too
        for k in range(1, len(at)):
            if not later[k - 1] or before[k] - since[k - 1] > NEAR_FRAMES:
                found = None  # a send again or a long silence: no proof until the next pair
                continue
            if named[k] != named[k - 1]:  # moved on: its only frame of that COUNTER since
                found = _only_named(enc_counter, good, since[k - 1] - RACE_FRAMES,
                                    int(before[k]), int(named[k]))
            elif found is not None and _only_named(enc_counter, good, found, int(before[k]),
                                                   int(named[k])) != found:
                found = None  # held, unless a newer frame of that COUNTER came: ambiguous
            if found is None:
                continue
            taken.add(int(good[found]))
            skipped.update(good[found + 1 : since[k - 1]].tolist())
    return Evidence(frozenset(taken), frozenset(skipped - taken))


def _sent_places(timestamp_s: npt.NDArray[np.float64], counter: IntArray,
                 before: IntArray, enc_s: npt.NDArray[np.float64]) -> list[int]:
    """Per pose frame (bus times ``timestamp_s``, COUNTERs ``counter``, ``before`` the good
    encoder frames before each on the bus, ``enc_s`` their bus times): the good encoder frames
    before it was sent. Its place on the bus when heard in order (``heard_in_order``), else
    those heard before the time it was sent, ``sent_times``' (a pose frame held back on the
    bus: its place is no bound)."""
    in_order, sent_s = sent_times(timestamp_s, counter, POSE_PERIOD_S)
    places: list[int] = before.tolist()
    late = [k for k, ordered in enumerate(in_order) if not ordered]
    sent = np.searchsorted(enc_s, np.array([sent_s[k] for k in late], dtype=np.float64), "right")
    for k, place in zip(late, sent.tolist(), strict=True):  # (one search for them all)
        places[k] = min(places[k], place)
    return places


def heard_in_order(timestamp_s: npt.NDArray[np.float64], counter: IntArray,
                   period_s: float) -> list[bool]:
    """``sent_times``' first list."""
    return sent_times(timestamp_s, counter, period_s)[0]


def sent_times(timestamp_s: npt.NDArray[np.float64], counter: IntArray,
               period_s: float) -> tuple[list[bool], list[float]]:
    """``send_readings``' first two lists."""
    ordered, sent, _ = send_readings(timestamp_s, counter, period_s)
    return ordered, sent


def send_readings(timestamp_s: npt.NDArray[np.float64], counter: IntArray,
                  period_s: float) -> tuple[list[bool], list[float], list[bool]]:
    """Whether each frame of one periodic sender (bus order; ``counter``: its E2E COUNTERs,
    ``period_s`` its send period) was sent after every frame of it heard before it: False for
    a frame held back on the bus behind a later send (``pose_evidence``). The sends between it
    and the latest-sent frame heard so far: the integer congruent to their COUNTER step mod 16
    nearest their stamps' gap in periods (exact while a frame comes less than 8 periods late,
    as ``e2e_periods.receive_periods``, and while a recorder that bunched the stamps shortened
    no gap by 8 periods: a frame taken late for that only proves nothing). A frame late behind
    sends that were all late too, or lost, is not told: it counts as in order, as before.
    The second list: when each was sent, its bus time if in order, else that of the latest
    sent before it heard, less the sends between (that one taken as heard when sent).

    The third: the frames not read at all (``lapped``; as ``host.judge.latenames.LateScan``): a
    frame held back half a COUNTER lap or more reads as sent ahead of the sender's cadence,
    and every on-time frame after it as late. Left in order where heard, it moves nothing
    (issue #11, rule 5: kobuki, figure8, seed 843, ``delay=0.1:200``: an ODOM_POSE_Y held
    back 10 sends read 7 ahead, the on-time ones after it late by 4 to 6 sends, and a late
    one naming the firmware's ENC_COUNTER 15 of 4.51 s proved the on-time encoder frame 15 of
    4.63 s taken, which the firmware had refused (its window locked on the late ones): the
    host took 10 frames the firmware refused, re-primed twice where it did not, and FAILed
    it at 288.6 mm off the reference, 0.25 mm off the truth)."""
    ordered: list[bool] = []
    sent: list[float] = []
    unread: list[bool] = []
    top_counter, top_s = -1, 0.0  # the latest-sent frame heard so far (-1: none yet)
    silence = 0.0  # periods beyond its COUNTER step before the latest-sent frame's run
    stamps, counters = timestamp_s.tolist(), counter.tolist()
    for k, (t_s, c) in enumerate(zip(stamps, counters, strict=True)):
        if top_counter >= 0:
            sends, x = _sends(t_s - top_s, c - top_counter, period_s)
            if not sends > 0:  # sent before (or a repeat of) a frame already heard: late
                ordered.append(False)
                sent.append(min(t_s, top_s + sends * period_s))
                unread.append(False)
                continue
            lead = sends - x
            if lapped(lead, silence) and k + 1 < len(stamps) and _on_cadence(
                    *_sends(stamps[k + 1] - top_s, counters[k + 1] - top_counter, period_s)):
                ordered.append(True)  # left where heard: the latest-sent frame kept
                sent.append(t_s)
                unread.append(True)
                continue
            if x - sends >= LATE_CYCLES or lead >= LATE_CYCLES:
                silence = max(x - sends, 0.0)  # after a silence; or on time after a late run
        ordered.append(True)
        sent.append(t_s)
        unread.append(False)
        top_counter, top_s = c, t_s
    return ordered, sent, unread


def _sends(dt_s: float, step: int, period_s: float) -> tuple[int, float]:
    """The sends a frame ``step`` COUNTERs (mod 16) and ``dt_s`` after another lies after it
    (``send_readings``: the nearest to the gap's periods), and that gap in periods."""
    x = dt_s / period_s
    step &= ENC_COUNTER_MASK
    return step + COUNTER_MODULO * math.floor((x - step + COUNTER_MODULO // 2)
                                              / COUNTER_MODULO), x


def _on_cadence(sends: int, x: float) -> bool:
    """A frame ``sends`` after the latest-sent one, ``x`` periods after it, on time: the frame
    before it that read lapped was one late among frames on time, not the first of a new run (a
    rebooted sender's COUNTER starting again, frames a bus-off held), whose frames after it all
    read lapped from the frame before the run, and which is read in order as before."""
    return sends > 0 and sends - x < LATE_CYCLES


def lapped(ahead: float, silence: float) -> bool:
    """Whether a frame read in order ``ahead`` periods sooner than its COUNTER step from the
    latest-sent frame puts its send (those before it read ``ahead`` periods late, were it on
    time) is rather held back half a COUNTER lap or more (lap - ``ahead`` periods): the
    COUNTER cannot tell the two; the run of that latest-sent frame can. Held back ``ahead``
    periods, it started after a silence that long beyond its COUNTER step (``silence``); at
    the sender's cadence since a frame on time, it was on time (delay=0.1:200 read so: a
    frame 10 periods late, 6 ahead of the on-time one before it, moved every on-time frame
    after it 120 ms back, to the wrong encoder frames). Moved here from
    ``host.judge.latenames`` (which re-exports it) for ``send_readings``."""
    return ahead >= LATE_CYCLES and abs(silence - ahead) > HALF_PERIOD


def _only_named(enc_counter: IntArray, good: npt.NDArray[np.intp], lo: int, hi: int,
                named: int) -> int | None:
    """The place in ``good`` of the one good encoder frame with COUNTER ``named`` among places
    ``lo`` .. ``hi`` - 1; None when there is none or more than one."""
    places = [k for k in range(max(lo, 0), hi) if int(enc_counter[good[k]]) == named]
    return places[0] if len(places) == 1 else None


def settle(crc_ok: npt.NDArray[np.bool_], counter: IntArray,
           periods: tuple[IntArray, IntArray, IntArray], evidence: Evidence,
           max_delta_init: int, released: npt.NDArray[np.bool_],
           new_cycle: tuple[npt.NDArray[np.float64], float] | None = None,
           reading: npt.NDArray[np.int8] | None = None) -> npt.NDArray[np.int8]:
    """One message's statuses (bus order) judged with the three readings' ``periods`` (strict,
    wide, narrow) and, where it speaks, with ``evidence``, else by the strict reading, or
    the wide one after a frame a stalled recorder ``released``, or the one ``reading`` names
    for the frame (0 strict, 1 wide, 2 narrow; -1 none: ``e2e_pages``). The Profile 2 check of
    ``host.protocol.e2e.SequenceState`` with three windows, its new-cycle rule included
    (``new_cycle``: the frames' bus times and the message's period; ``e2e_cycles``)."""
    n = len(counter)
    status = np.full(n, S_CRC, dtype=np.int8)
    waiting, last, last_s = True, 0, math.nan
    anchored = False  # the last frame taken is the firmware's E2E check's last (``_bound_skip``)
    columns = [p.tolist() for p in periods]
    windows_at = Windows(columns)  # read where a frame needs them (``e2e_windows``)
    ok, counters = crc_ok.tolist(), (counter & ENC_COUNTER_MASK).tolist()
    late = released.tolist()
    chosen = reading.tolist() if reading is not None else [-1] * n
    stamps, cycle_s = (new_cycle[0].tolist(), new_cycle[1]) if new_cycle else ([], 0.0)
    taken: list[int] = []  # the frames taken so far (``e2e_retract``)
    cums = (windows_at.sums[1], windows_at.sums[2])  # the periods summed once (e2e_windows)
    for j in np.flatnonzero(crc_ok).tolist():  # a bad CRC only widens the windows
        delta = (counters[j] - last) & ENC_COUNTER_MASK
        if waiting or delta == 1:
            code = S_OK
        elif delta == 0:
            if stamps and not waiting and new_cycles(stamps[j] - last_s, cycle_s):
                status[j], last_s = S_LOST, stamps[j]  # the sender's frame 16 k on: window kept
                continue
            status[j], last_s = S_REPEATED, math.nan  # a frame between: no new cycle till next
            continue
        else:
            windows = windows_at.at(j)
            which = chosen[j] if chosen[j] >= 0 else int(late[j - 1]) if j else 0
            code = _by_window_or_evidence(j, delta, windows[which], evidence)
            if code == S_WRONG and anchored and _bound_skip(j, delta, windows, evidence,
                                                            taken[-1]):
                code = S_LOST  # taken by the E2E check, refused by the plausibility bound
            if j in evidence.taken and delta > max(windows):  # the host's last is not its
                code = _taken_back(j, taken, counters, ok, cums, max_delta_init, evidence,
                                   status)
                if code < 0:  # no frame it took leads there: a skip was the bound's
                    code = _retaken(j, taken, evidence, status, Readings(
                        ok, counters, columns, chosen, late, max_delta_init))
        status[j] = code
        if code != S_WRONG:
            taken.append(j)
            anchored = j in evidence.taken or (
                anchored and (delta == 1 or exact(delta, windows_at.at(j))))
            waiting, last = False, counters[j]
            windows_at.reset(j, max_delta_init)
            last_s = stamps[j] if stamps else math.nan
        else:
            last_s = math.nan
    return status


def _taken_back(j: int, taken: list[int], counters: list[int], ok: list[bool],
                cums: tuple[list[int], list[int]], max_delta_init: int, evidence: Evidence,
                status: npt.NDArray[np.int8]) -> int:
    """The status of frame ``j``, proven taken though every window refuses it: the frames
    ``taken`` after the firmware's last (``e2e_retract.firmware_last``) are refused
    (``status`` and ``taken`` edited in place); OKSOMELOST (or OK one COUNTER on); -1 when
    no frame the host took can have been the firmware's last (``e2e_implausible``)."""
    place = firmware_last(j, taken, counters, ok, cums, max_delta_init, evidence.taken)
    if place is None:
        return -1
    for q in taken[place + 1 :]:
        status[q] = S_WRONG
    del taken[place + 1 :]
    return S_OK if (counters[j] - counters[taken[-1]]) & ENC_COUNTER_MASK == 1 else S_LOST


def _retaken(j: int, taken: list[int], evidence: Evidence, status: npt.NDArray[np.int8],
             frames: Readings) -> int:
    """The status of frame ``j``, proven taken, where no frame the host took can have led to
    it: the frames from the last one proven taken judged by the stamps alone where that leads
    to it (``e2e_implausible.by_stamps``: ``status`` and ``taken`` edited in place), else left
    as they were; OKSOMELOST (or OK one COUNTER on)."""
    retaken = by_stamps(j, taken, evidence.taken, evidence.skipped, frames)
    if retaken is None:
        return S_LOST
    for q, code in retaken.codes.items():
        status[q] = code
    del taken[retaken.place + 1 :]
    taken.extend(retaken.taken)
    step = (frames.counters[j] - frames.counters[taken[-1]]) & ENC_COUNTER_MASK
    return S_OK if step == 1 else S_LOST


def _bound_skip(j: int, delta: int, windows: list[int], evidence: Evidence, last: int) -> bool:
    """Whether frame ``j``, ``delta`` COUNTERs after the host's last taken frame (the firmware E2E
    check's last: proven taken, or reached from such a frame by steps the readings' one window
    takes), proven skipped, was rather taken by the E2E check and refused by the plausibility bound
    (``e2e_implausible``): the three readings' windows are one and take it (``exact``), so the
    stamps say the check took it. Such a frame moves the check's COUNTER on, and the frames on time
    after it are its repeats or out of sequence (issue #11: kobuki, seed 3, ``delay=0.5:150``: the
    late COUNTER 5 of 4.20 s, sent 4.05 s, 2 after the late 3 the check took after the on-time 2;
    the bound refused both, and the firmware refused the on-time 5 of 4.21 s as REPEATED. The host
    read the skip as the check's and took that 5, 278 counts of path the firmware never drove:
    ODOM_TWIST DISTANCE 17.0 mm off a right firmware). Or every window takes it and its counts
    from ``last`` say the bound refused it (``e2e_bound.by_counts``)."""
    return j in evidence.skipped and (exact(delta, windows) or by_counts(
        evidence.beyond, delta, windows, last, j))


def _by_window_or_evidence(j: int, delta: int, window: int, evidence: Evidence) -> int:
    """OKSOMELOST or WRONG_SEQUENCE for a frame ``delta`` after the last taken one: the
    evidence's where it speaks, even where the readings agree (module docstring), else by the
    ``window`` of the reading chosen for it."""
    if j in evidence.taken:
        return S_LOST
    if j in evidence.skipped:
        return S_WRONG
    return S_LOST if delta <= window else S_WRONG


def recorder_releases(timestamp_s: npt.NDArray[np.float64], is_encoder: npt.NDArray[np.bool_],
                      cycle_s: float) -> npt.NDArray[np.bool_]:
    """Frames a stalled recorder stamped on its release: the log (every ID) silent for
    ``SILENCE_CYCLES`` periods, then a burst of an encoder frame and more, each stamped after
    the one before it by less than ``BURST_S`` but not at once (``ALIKE_S``). No bus delivers
    two frames that close (a classic CAN frame takes 47 us or more at 1 Mbit/s), and the rig
    stamps the frames of one instant alike (a gap of 0), so a silent stretch of its log (a
    20 ms pose period whose encoder frames were late or lost) is never taken for one."""
    released = np.zeros(len(timestamp_s), dtype=bool)
    if len(timestamp_s) < 2:
        return released
    gap_s = np.diff(timestamp_s, prepend=timestamp_s[:1])  # the log's start: no silence
    close = (gap_s > ALIKE_S) & (gap_s < BURST_S)
    apart = np.flatnonzero(~close)  # where each burst ends (the frame after it)
    for first in np.flatnonzero(gap_s >= SILENCE_CYCLES * cycle_s).tolist():
        k = int(np.searchsorted(apart, first, side="right"))
        end = int(apart[k]) if k < len(apart) else len(timestamp_s)
        if end - first >= 2 and bool(is_encoder[first:end].any()):
            released[first:end] = True
    return released


class ReleaseWatch:
    """``recorder_releases`` live, one frame (of any ID) at a time: ``seen`` notes a frame,
    ``released`` says whether the frame heard at a time came in a release (known once the frame
    after it came: a release is a silence then frames less than ``BURST_S`` apart, not at once).
    The encoder frames ask it for their pair's first frame, when the second comes."""

    __slots__ = ("_key", "_last_s", "_lone_s", "_mixed", "_releases", "_silence_s", "_woke_s")

    def __init__(self, cycle_s: float) -> None:
        self._silence_s = SILENCE_CYCLES * cycle_s
        self._last_s: float | None = None
        self._lone_s: float | None = None  # a frame after a silence, its burst not seen yet
        self._releases: list[tuple[float, float]] = []  # the recent ones (first, last s)
        self._woke_s = -math.inf  # the latest frame heard after a silence of a drive's bus (s)
        self._key = -1  # the message of the last frame heard
        self._mixed = False  # frames of two messages heard: a drive's bus, never that quiet

    def seen(self, timestamp_s: float, key: int = -1) -> None:
        """Note a frame heard at ``timestamp_s`` s (``key``: its message's)."""
        last, self._last_s = self._last_s, timestamp_s
        if not self._mixed:  # (once mixed, always: the message of the last frame not needed)
            self._mixed = last is not None and key != self._key
            self._key = key
        if last is None:
            return
        gap_s = timestamp_s - last
        if gap_s >= self._silence_s and self._mixed:
            self._woke_s = timestamp_s
        if gap_s >= BURST_S or gap_s <= ALIKE_S:  # the usual case: no burst
            self._lone_s = timestamp_s if gap_s >= self._silence_s else None
            return
        if self._releases and self._releases[-1][1] == last:
            self._releases[-1] = (self._releases[-1][0], timestamp_s)  # the burst goes on
        elif self._lone_s == last:
            self._releases = [*self._releases[-3:], (last, timestamp_s)]  # a burst: a release
        self._lone_s = None

    def released(self, timestamp_s: float | None) -> bool:
        """Whether the frame heard at ``timestamp_s`` s came in a release (asked per encoder
        frame of every robot: none noted, the usual case, is said without a generator)."""
        if not self._releases or timestamp_s is None:
            return False
        return any(first <= timestamp_s <= last for first, last in self._releases)

    def silent_after(self, timestamp_s: float | None) -> bool:
        """Whether the recorder heard nothing for ``SILENCE_CYCLES`` or more after the frame
        heard at ``timestamp_s`` s, up to the frame just seen, on a bus that carried frames of
        two messages or more (a drive's bus, never that quiet): it held the frames of both
        ends (issue #11, rule 5: the live recordings of a correct firmware, whose frames before
        such a hole were stamped 3.8 periods late, 50 to 100 us apart, no release, had the
        frames after it refused as WRONG_SEQUENCE and FAILed at 0.16 mm, and at 32.99 mm once a
        pose naming one was paired 16 periods off). A log of one sender's frames (its own gaps
        on a quiet bus) has no such silence."""
        return timestamp_s is not None and self._woke_s > timestamp_s
