"""A firmware reboot in its first second of uptime, told from its E2E COUNTERs: its power-up tick.

UPTIME (ODOM_STATUS, whole seconds) cannot tell a reset within the firmware's first second: the
new firmware says UPTIME 0 as the old one did, and when it primes on an encoder frame in its
first tick it says OK, not INIT (``host.judge.sources``). What tells it is what a firmware
speaking the DBC sends at power-up: its E2E COUNTERs start at 0 (E2E Profile 2: the sender's
counter starts at 0; ``powerup.holds_first_cycle`` relies on it too), and its first tick sends
its pose, then its summary (firmware/ecu.py step 5). The power-up tick's signature: a summary of
UPTIME 0 and COUNTER 0 heard less than ``BOOT_WINDOW_MS`` after an ODOM_POSE_X of COUNTER 0, the
poses heard since (their CRC holding, whatever their E2E sequence) counting on from it, the
latest of them with a COUNTER below ``BOOT_POSE_FRAMES`` (a pose run, ``next_run``). A summary
stamped in its tick (after its own pose) or held back behind the next poses of its new life (a
loaded bus, a recorder's stamping, up to ``BOOT_WINDOW_MS``) is told alike.

Within one firmware life the two COUNTERs read 0 in one tick again only once both wrapped
together: ODOM_POSE_X every 16 frames at one a 20 ms cycle (320 ms), ODOM_STATUS every 16 frames
at two a 100 ms cycle (800 ms): both every lcm = 1.6 s of sending (``JOINT_WRAP_MS``, from the
DBC's GenMsgCycleTime and E2EFramesPerCycle; the tests check them against the DBC). By then
UPTIME says 1 at least; a firmware that sent fewer frames (stalled, overrun) took longer still.
Between, a summary of COUNTER 0 comes a whole multiple of ``PHASE_STEP_MS`` = gcd(320, 800) =
160 ms after the latest pose of COUNTER 0 (the two started together at power-up): at 0.8 s it
is 160 ms and 8 pose frames after one. The window (half that step: 80 ms, 4 pose frames) keeps
it out with a margin for stamping; a summary of the old life would have to be held back 160 ms
or more (behind a later pose of COUNTER 0) to pass for a boot tick, the limit the same-tick rule
had too. Those phases hold from a life's first pose: a firmware INIT at power-up (no encoder
frame yet) sends summaries but no pose (firmware/reports.py), so its poses run 1 to 8 frames
behind and its summary of COUNTER 0 at 0.8 s came 0 to 60 ms after a pose of COUNTER 0 (the
motor controller 100..160 ms late: a false reboot mid-drive, at 160 ms already with the
same-tick rule). So one of the two must also break its own message's sequence: the run's pose
of COUNTER 0 that of the pose heard before it (``breaks_sequence``), or the summary that of the
ODOM_STATUS frame heard before it (``status_breaks``): sooner than one life could count on to 0
(one life's frames never come faster than their cycle; lost ones, stalls, an INIT: later). A
new firmware breaks at least one: its first frames come within a tick of the old one's last,
and the old COUNTERs would have to be one period short of 0 for both (not within the first
second: 32 and 96 ticks in, the pose alone continues; 80, the status alone). So within UPTIME 0
the signature is a new firmware.
A COUNTER 0 after a COUNTER 0 (E2E REPEATED) breaks no sequence (``REPEAT_NO_BREAK``): a
firmware whose E2E COUNTER does not advance sends COUNTER 0 in every frame, and was told
rebooting at every summary of its first second (9 reboots at 0.10 .. 0.90 s, its pose then
judged against 9 power-up references: 51.9 mm off, 0.000 m travelled, where the fault is the
E2E counter: ``host.judge.verdictfacts``). A real reset heard as a repeat of both (the old
life's last pose and status frames of COUNTER 0: its own first tick) is not told this way.
Lost frames cannot make it up: they shorten no time and the COUNTERs are read, not counted (a
COUNTER that jumps to 0 is also what 16 k - j lost frames look like, so a jump alone is no
evidence, and one ID alone is not either: ODOM_STATUS wraps at 0.8 s). A recorder's repeat of
the boot summary is no second boot: the summary before it must be at least ``REPEAT_S`` older.
The judges that heard the new life's first poses and twists before its held-back summary
withdraw them (``SourceWatch.life_from_s``).

Why this rather than a finer UPTIME (a DBC change): a user's own firmware that speaks the DBC
gives it as it is (E2E counters from 0, the DBC's cycles), ours and the C port alike, and old
logs are judged the same.

A firmware whose first tick sends its summary (OK) but no pose has no pose of COUNTER 0 before
that summary: it is told looking ahead. The first pose after it (``boot_ahead``): COUNTER 0,
less than ``BOOT_WINDOW_MS`` after the summary, no summary between, the pose or the summary
breaking its sequence (a new firmware came). Which life the summary is of, the next summary
tells (``continues_summary``): a new firmware's continues the summary's sequence (COUNTER 2,
UPTIME 0, a cycle on). An old life's summary of COUNTER 0 (at 0.8 s) does not pass: held back
behind later ones (it breaks the status sequence, and held back more than 80 ms its next pose
of COUNTER 0, 160 ms on in its life, comes within 80 ms of it) the next summary continues the
sequence it broke; followed by a reboot whose firmware sent its pose first (it breaks the pose
sequence), the next summary is that firmware's boot summary, COUNTER 0 (told by its run). The
live judges hold that verdict until that summary (a cycle), then start the life at the
looked-ahead summary's encoder frame and withdraw what they judged since; the streamed
``analyze`` holds the events after the summary across chunks (``stream_lives``). A pose or a
status frame the bus held back breaks no sequence there either (``aheadticks``: the summary of
COUNTER 0 every 0.8 s of UPTIME 0, a held-back pose after it, was told a second reboot).
A reset 32 k ticks in whose power-up pose the bus lost breaks no pose COUNTER (the old life's
last read 15): the twist's DISTANCE going back is its second evidence (``host.judge.distfall``).
A pose with no pose heard before breaks nothing once ODOM_STATUS frames were heard (a firmware
INIT before its first pose: ``initfirst``). One rule, for every judge: ``SourceWatch.observe``
(the live monitor, the bridge, the streamed ``analyze``; ``hear_pose`` and ``told_ahead`` live)
and ``boot_ticks`` and ``aheadticks`` (the whole log's quiet stretches,
``SourceWatch.observe_quiet``).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.distfall import Falls, any_tied
from odocan.host.judge.initfirst import first_pose_breaks, status_before_first
from odocan.host.protocol import busfacts
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e import crc8h2f_p02, crc8h2f_p02_one, e2e_messages

POSE_MESSAGE = busfacts.POSE_MESSAGE  # the pose frame the firmware's every tick sends first
STATUS_MESSAGE = busfacts.STATUS_MESSAGE  # its summary and pages
# The DBC's (``host.protocol.busfacts``): 16, 20 ms, 1 a cycle; 16, 100 ms, 2 a cycle; 1 s
POSE_COUNTER_LAP, POSE_CYCLE_MS = busfacts.POSE_COUNTER_LAP, busfacts.POSE_CYCLE_MS
POSE_FRAMES_PER_CYCLE = busfacts.POSE_FRAMES_PER_CYCLE
STATUS_COUNTER_LAP, STATUS_CYCLE_MS = busfacts.STATUS_COUNTER_LAP, busfacts.STATUS_CYCLE_MS
STATUS_FRAMES_PER_CYCLE = busfacts.STATUS_FRAMES_PER_CYCLE
JOINT_WRAP_MS = math.lcm(POSE_COUNTER_LAP * POSE_CYCLE_MS // POSE_FRAMES_PER_CYCLE,
                         STATUS_COUNTER_LAP * STATUS_CYCLE_MS // STATUS_FRAMES_PER_CYCLE)
UPTIME_LSB_MS = busfacts.UPTIME_LSB_MS  # ODOM_STATUS UPTIME: 1 s per LSB
# The rule's ground (module docstring): 1600 ms >= 1000 ms. A DBC whose two COUNTERs wrap
# together within one UPTIME LSB cannot tell a reboot this way: then no summary is a boot tick.
RULE_HOLDS = JOINT_WRAP_MS >= UPTIME_LSB_MS
# Within one life a summary of COUNTER 0 comes a multiple of this after the latest pose of
# COUNTER 0 (the two COUNTERs' laps, 320 and 800 ms: 160 ms); only the joint wrap's multiple is 0
PHASE_STEP_MS = math.gcd(POSE_COUNTER_LAP * POSE_CYCLE_MS // POSE_FRAMES_PER_CYCLE,
                         STATUS_COUNTER_LAP * STATUS_CYCLE_MS // STATUS_FRAMES_PER_CYCLE)
BOOT_WINDOW_MS = PHASE_STEP_MS // 2  # a boot summary heard this soon after the new pose run's 0
BOOT_WINDOW_S = BOOT_WINDOW_MS / 1000
# the pose frames sent in the window: the run's latest COUNTER stays below it (80 ms: 4)
BOOT_POSE_FRAMES = BOOT_WINDOW_MS * POSE_FRAMES_PER_CYCLE // POSE_CYCLE_MS
REPEAT_S = POSE_CYCLE_MS / 4000  # a summary this close after the one before: a repeat of it
# (start bus times, latest COUNTERs, starts breaking the sequence) of pose runs, per summary
Runs = tuple[npt.NDArray[np.float64], npt.NDArray[np.int64], npt.NDArray[np.bool_]]
Latest = tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]  # bus times, COUNTERs
POSE_PERIOD_S = busfacts.POSE_PERIOD_S  # one pose frame to the next: 20 ms
# a pose of COUNTER 0 this much sooner than one life's next COUNTER 0 could come breaks the
# sequence (stamps of one life's poses taken to be this exact: a quarter of a pose cycle)
SEQUENCE_SLACK_S = POSE_CYCLE_MS / 4000
STATUS_CYCLE_S = busfacts.STATUS_CYCLE_S  # one summary to the next: 100 ms
# a fall this long after a summary at most may tie to it (``tied_to_boot``: by the next summary)
FALL_AFTER_S = max(BOOT_WINDOW_S, STATUS_CYCLE_S + SEQUENCE_SLACK_S)
TWIST_COUNTERS = POSE_COUNTER_LAP  # the falls read at any COUNTER: ``tied_to_boot`` picks


def breaks_sequence(counter_before: int, since_s: float) -> bool:
    """Whether an ODOM_POSE_X of COUNTER 0 heard ``since_s`` after one of ``counter_before``
    comes too soon for one firmware life: that life sends ``POSE_COUNTER_LAP - counter_before``
    frames (at least: frames lost between are more) one ``POSE_PERIOD_S`` apart to get there
    (ticks run, never faster: a stall or an INIT without poses only takes longer)."""
    lap = POSE_COUNTER_LAP
    return bool(counter_before != 0  # a repeat is no break (``REPEAT_NO_BREAK``)
                and since_s < (lap - counter_before) * POSE_PERIOD_S - SEQUENCE_SLACK_S)


def status_breaks(counter_before: int, since_s: float) -> bool:
    """Whether a summary of COUNTER 0 heard ``since_s`` after an ODOM_STATUS frame of
    ``counter_before`` (any page) comes too soon for one firmware life: it sends its frames
    ``STATUS_FRAMES_PER_CYCLE`` a cycle (the summary first), so it gets from that one's cycle to
    the summary of COUNTER 0 in ``(STATUS_COUNTER_LAP - counter_before) // 2``-ish cycles, never
    sooner (lost frames, stalls: later)."""
    per = STATUS_FRAMES_PER_CYCLE
    cycles = STATUS_COUNTER_LAP // per - counter_before // per
    return bool(counter_before != 0  # a repeat is no break (``REPEAT_NO_BREAK``)
                and since_s < cycles * STATUS_CYCLE_MS / 1000 - SEQUENCE_SLACK_S)


def next_run(run: tuple[float, int, bool] | None, t_s: float, counter: int,
             before_s: float | None, status_heard: bool = False) -> tuple[float, int, bool]:
    """The pose run after an ODOM_POSE_X of E2E ``counter`` heard at bus time ``t_s`` (its CRC
    holding): (bus time of the run's pose of COUNTER 0, NaN when the COUNTERs did not count on
    from one since; the latest COUNTER; whether that pose of COUNTER 0 ``breaks_sequence`` of
    the pose heard before it, or had none). ``run``: the one before (None: no pose yet);
    ``before_s``: the bus time of the pose heard before (None: none). A pose of COUNTER 0 starts
    a run; one whose COUNTER is above the latest continues it (frames lost between keep it:
    they take no time away); any other breaks it. One with no pose before breaks it only when
    no ODOM_STATUS frame was heard before either (``status_heard``: ``initfirst``)."""
    if counter == 0:
        if run is None or before_s is None:
            return t_s, 0, first_pose_breaks(status_heard)
        return t_s, 0, breaks_sequence(run[1], t_s - before_s)
    if run is not None and counter > run[1]:
        return run[0], counter, run[2]
    return math.nan, counter, False


def boot_tick(uptime_s: int, counter: int, t_s: float, pose: tuple[float, int, bool] | None,
              summary_before_s: float | None, status_before: tuple[float, int] | None,
              fell: bool = False, held: bool = False) -> bool:
    """The summary (UPTIME ``uptime_s``, E2E ``counter``, bus time ``t_s``) is a firmware's
    power-up tick (module docstring): ``pose``, the pose run of the ODOM_POSE_X frames heard
    before it (``next_run``; None: none); ``summary_before_s``: the bus time of the summary
    before (None: none); ``status_before``: bus time and COUNTER of the ODOM_STATUS frame
    heard before it (any page; None: none). The run's pose of COUNTER 0 or the summary must
    break its message's sequence (``breaks_sequence``, ``status_breaks``), or the twists'
    DISTANCE fell in the run's window (``fell``: ``fell_in_run``). ``held``: the summary or
    the ODOM_STATUS frame before it was held back by the bus (``livelatestatus``): their
    COUNTERs' step says nothing of a new life (``SourceWatch.observe``)."""
    if not RULE_HOLDS or uptime_s != 0 or counter != 0 or pose is None:
        return False
    if summary_before_s is not None and t_s - summary_before_s < REPEAT_S:
        return False
    broken = fell or pose[2] or (not held and (status_before is None or status_breaks(
        status_before[1], t_s - status_before[0])))
    return broken and 0 <= pose[1] < BOOT_POSE_FRAMES and 0.0 <= t_s - pose[0] < BOOT_WINDOW_S


def told_run_s(uptime_s: int, counter: int, t_s: float, pose: tuple[float, int, bool] | None
                ) -> float | None:
    """Where a reboot UPTIME already told (it went back) began, when its boot summary (UPTIME
    0, ``counter`` 0, bus time ``t_s``) came after the new life's first poses (``pose``, the
    run before it: ``next_run``): the bus time of that run's pose of COUNTER 0 within the
    window (``boot_tick``'s, no sequence break asked: the reboot is told), else None. A
    recorder stamping ODOM_STATUS 50 ms late put the boot summary after the new firmware's
    first three poses, which the live judges held to the old life's reference (1.46 m, POSE
    WRONG, end verdict FAIL of a correct firmware: issue #11)."""
    if not RULE_HOLDS or uptime_s != 0 or counter != 0 or pose is None:
        return None
    in_run = 0 <= pose[1] < BOOT_POSE_FRAMES and 0.0 <= t_s - pose[0] < BOOT_WINDOW_S
    return pose[0] if in_run else None


def ahead_candidate(uptime_s: int, counter: int, t_s: float, summary_before_s: float | None,
                    status_before: tuple[float, int] | None) -> bool | None:
    """A summary that is no ``boot_tick`` but may be a power-up tick that sent no pose (its
    first pose comes after it: ``boot_ahead``): None when it cannot be (not UPTIME 0 and
    COUNTER 0, or a repeat); else whether it breaks the ODOM_STATUS sequence (``status_breaks``
    of the frame heard before it; none: True)."""
    if not RULE_HOLDS or uptime_s != 0 or counter != 0:
        return None
    if summary_before_s is not None and t_s - summary_before_s < REPEAT_S:
        return None
    return status_before is None or status_breaks(status_before[1], t_s - status_before[0])


def boot_ahead(summary_s: float, status_broke: bool, t_s: float, counter: int,
               before: tuple[float, int] | None, fell: bool = False) -> bool:
    """Whether the first ODOM_POSE_X heard after an ``ahead_candidate`` summary (bus time
    ``summary_s``; ``status_broke``: it broke the ODOM_STATUS sequence) may make that summary a
    power-up tick whose firmware sent no pose in it (the pose at bus time ``t_s``, E2E
    ``counter``, its CRC holding; ``before``: bus time and COUNTER of the pose heard before it,
    None: none; no other summary between them: the caller's): COUNTER 0 less than
    ``BOOT_WINDOW_S`` after the summary, the pose or the summary breaking its message's
    sequence; or, its power-up pose lost on the bus, a small COUNTER restarted
    (``restarts_small``) after a summary that broke the ODOM_STATUS sequence (issue #11: a reset
    10..60 ticks into the firmware's first second, its first pose pair lost, FAILed the correct
    firmware 9 mm..0.23 m in every judge), or the twist's DISTANCE fell (``fell``: a twist of
    a small COUNTER below the one before, ``fell_around``) where that COUNTER continues the old
    life's (a reset 32 k ticks in: the correct firmware FAILed 93 mm..0.41 m). The next
    summary tells (``continues_summary``)."""
    soon = RULE_HOLDS and 0.0 <= t_s - summary_s < BOOT_WINDOW_S
    if counter != 0:  # its power-up pose lost: a second message's sequence or DISTANCE broke
        small = 0 < counter < BOOT_POSE_FRAMES
        return bool(soon and status_broke and small
                    and (fell or restarts_small(counter, t_s, before)))
    broke = status_broke or (before is not None  # none: a summary came first (``initfirst``)
                             and breaks_sequence(before[1], t_s - before[0]))
    return bool(soon and broke)


def tied_to_boot(t_s: float, counter: int, summary_s: float) -> bool:
    """Whether a twist (bus time ``t_s``, E2E ``counter``) whose DISTANCE fell may be the new
    firmware's of a power-up tick at the summary at ``summary_s`` (``fell_around``): less than
    ``BOOT_WINDOW_S`` from it either side with a COUNTER below ``BOOT_POSE_FRAMES`` (its tick's
    twist comes before it, that one lost the next ones, COUNTER 1..3, after); or heard after it
    by the next summary (``STATUS_CYCLE_S`` on: ``continues_summary`` reads it then, live all
    those twists heard) with no more twists counted than the time since the summary allows
    (ODOM_TWIST shares the pose's cycle: COUNTER c comes c ``POSE_PERIOD_S`` after the power-up
    twist, never sooner). The second holds the new firmware's first 4 or 5 twists lost as well
    (issue #11: the first heard, COUNTER 4 80 ms on, past the window, the correct firmware
    FAILed by 93 mm in every judge). The fall itself says a new life began since the twist
    before it; the summary (UPTIME 0, COUNTER 0, breaking the ODOM_STATUS sequence, its first
    pose's COUNTER small and soon, the next summary continuing it) says where."""
    since_s = t_s - summary_s
    near = abs(since_s) <= BOOT_WINDOW_S and counter < BOOT_POSE_FRAMES
    after = (0.0 < since_s <= STATUS_CYCLE_S + SEQUENCE_SLACK_S
             and counter * POSE_PERIOD_S <= since_s + SEQUENCE_SLACK_S)
    return bool(near or after)


def fell_around(falls: Falls, summary_s: float) -> bool:
    """Whether a twist's DISTANCE fell (``distfall.fall_times``, bus times in order) where it
    ties to a power-up tick at the summary at ``summary_s`` (``tied_to_boot``):
    ``boot_ahead``'s ``fell``. Live, told at the next summary, a cycle on."""
    return any_tied(falls, summary_s - BOOT_WINDOW_S, summary_s + FALL_AFTER_S,
                    lambda t_s, counter, _before_s: tied_to_boot(t_s, counter, summary_s))


def tied_to_run(t_s: float, counter: int, summary_s: float) -> bool:
    """Whether a twist (bus time ``t_s``, E2E ``counter``) whose DISTANCE fell is the new
    firmware's of a power-up tick whose summary at ``summary_s`` came after its poses
    (``boot_tick``): heard by the summary, less than ``BOOT_WINDOW_S`` before it, COUNTER below
    ``BOOT_POSE_FRAMES`` (the run's own twists: ODOM_TWIST shares the pose's cycle). A reset in
    the firmware's first second followed by 0.3 s or more of boot silence (``reboot=0.5:0.5``)
    breaks neither COUNTER sequence (one life losing its frames on the bus could count on to 0
    in that time), and UPTIME says 0 in both lives: it was told a stall and the new life's
    DISTANCE from 0 FAILed the correct firmware (90..162 mm, issue #11). A stalled firmware's
    DISTANCE goes on from where it was; one that fell is a new life."""
    since_s = summary_s - t_s
    return bool(0.0 <= since_s < BOOT_WINDOW_S and counter < BOOT_POSE_FRAMES)


def fell_in_run(falls: Falls, summary_s: float) -> bool:
    """Whether a twist's DISTANCE fell (``distfall.fall_times``, bus times in order) where it
    is the pose run's before the summary at ``summary_s`` (``tied_to_run``): ``boot_tick``'s
    ``fell``, read when the summary is heard (live: ``distfall.fell_within``)."""
    return any_tied(falls, summary_s - BOOT_WINDOW_S, summary_s,
                    lambda t_s, counter, _before_s: tied_to_run(t_s, counter, summary_s))


def restarts_small(counter: int, t_s: float, before: tuple[float, int] | None) -> bool:
    """Whether an ODOM_POSE_X of E2E ``counter`` (1 .. ``BOOT_POSE_FRAMES`` - 1) heard at bus
    time ``t_s`` is a new firmware's whose power-up pose the bus lost: its COUNTER restarted
    small, sooner than one life could count on to it from the pose heard before (``before``:
    bus time, COUNTER; None: no pose before, nothing to break). One life sends the
    ``(counter - COUNTER before) mod 16`` frames between (16 for the same COUNTER) one
    ``POSE_PERIOD_S`` apart, never faster (lost frames, stalls: later). The summary's own break
    is the caller's (``boot_ahead``): two messages' sequences broken, not one."""
    if before is None or not 0 < counter < BOOT_POSE_FRAMES:
        return False
    return sooner_than_one_life(counter, t_s, before)


def sooner_than_one_life(counter: int, t_s: float, before: tuple[float, int]) -> bool:
    """Whether an ODOM_POSE_X of E2E ``counter`` heard at bus time ``t_s`` came sooner than one
    life could count on to it from the pose ``before`` (bus time, COUNTER): the
    ``(counter - COUNTER before) mod 16`` frames between (16 for the same COUNTER) are sent one
    ``POSE_PERIOD_S`` apart, never faster."""
    frames = (counter - before[1] - 1) % POSE_COUNTER_LAP + 1
    return bool(t_s - before[0] < frames * POSE_PERIOD_S - SEQUENCE_SLACK_S)


def continues_summary(summary_s: float, t_s: float, uptime_s: int, counter: int) -> bool:
    """Whether the next summary (bus time ``t_s``, UPTIME ``uptime_s``, E2E ``counter``) after
    a summary of COUNTER 0 at ``summary_s`` whose first pose ``boot_ahead`` took continues that
    one's sequence, as the new firmware's next does: UPTIME 0 and the next cycle's COUNTER,
    within two cycles (module docstring; a summary lost: not told, no PASS given for it)."""
    return (uptime_s == 0 and counter == STATUS_FRAMES_PER_CYCLE % STATUS_COUNTER_LAP
            and 0.0 < t_s - summary_s < 2 * STATUS_CYCLE_MS / 1000)


def boot_ticks(uptime_s: npt.NDArray[np.int64], counters: npt.NDArray[np.int64],
               t_s: npt.NDArray[np.float64], poses: Runs, statuses: Latest,
               summary_before_s: float | None, falls: Falls | None = None
               ) -> npt.NDArray[np.bool_]:
    """``boot_tick`` of summaries in bus order (their UPTIMEs, COUNTERs, bus times) at once;
    ``poses``: each one's pose run (``poses_before``: NaN, -1, False where none);
    ``statuses``: each one's ODOM_STATUS frame before (``status_before``: NaN, -1 where none);
    ``summary_before_s``: the bus time of the summary before the first; ``falls``: the twists
    whose DISTANCE fell (``fell_in_run``; None: none read)."""
    before = np.concatenate(([-math.inf if summary_before_s is None else summary_before_s],
                             t_s[:-1]))
    pose_t, pose_counter, pose_new = poses
    status_t, status_counter = statuses
    per = STATUS_FRAMES_PER_CYCLE
    cycles = STATUS_COUNTER_LAP // per - status_counter // per
    status_new: npt.NDArray[np.bool_] = (
        (status_counter < 0)
        | ((status_counter != 0)  # a repeat is no break (``REPEAT_NO_BREAK``)
           & (t_s - status_t < cycles * STATUS_CYCLE_MS / 1000 - SEQUENCE_SLACK_S)))
    since = t_s - pose_t  # NaN where no pose: every comparison False
    found: npt.NDArray[np.bool_] = (RULE_HOLDS & (uptime_s == 0) & (counters == 0)
                                    & (pose_counter >= 0) & (pose_counter < BOOT_POSE_FRAMES)
                                    & (t_s - before >= REPEAT_S)
                                    & (since >= 0.0) & (since < BOOT_WINDOW_S))
    broken = pose_new | status_new
    if falls is not None and len(falls.times_s):  # rare: read only where the rest holds
        for i in np.flatnonzero(found & ~broken).tolist():
            broken[i] = fell_in_run(falls, float(t_s[i]))
    return found & broken


def poses_before(frames: FrameArrays, decoder: BulkDecoder, positions: npt.NDArray[np.int64],
                 carried: tuple[float, int, bool, float] | None = None,
                 status_carried: bool = False
                 ) -> tuple[Runs, tuple[float, int, bool, float] | None]:
    """For the frames at ``positions`` (in order) the pose run of the ODOM_POSE_X frames before
    each whose CRC holds (``next_run``: its start's bus time, its latest COUNTER, whether its
    start broke the sequence; NaN, -1, False where none; ``carried``: the run of the frames
    before ``frames`` and its latest pose's bus time, a stream's earlier chunks), and that after
    them all (the next chunk's ``carried``). The first pose breaks the sequence only with no
    ODOM_STATUS frame before it (``initfirst``; ``status_carried``: an earlier chunk had one)."""
    where, t_pose, counter = _rows(frames, decoder, POSE_MESSAGE)
    first_new = carried is None and len(where) > 0 and first_pose_breaks(status_before_first(
        _rows(frames, decoder, STATUS_MESSAGE)[0], where, status_carried))
    if carried is not None:
        where = np.concatenate(([-1], where))
        t_pose = np.concatenate(([carried[3]], t_pose))
        counter = np.concatenate(([carried[1]], counter))
    if len(where) == 0:
        n = len(positions)
        return (np.full(n, math.nan), np.full(n, -1, np.int64), np.zeros(n, bool)), None
    start, new = _run_starts(t_pose, counter, None if carried is None else (carried[0], carried[2]),
                             first_new)
    k = np.searchsorted(where, positions) - 1  # the latest strictly before each
    found = k >= 0
    at = np.maximum(k, 0)
    times = np.where(found, start[at], math.nan).astype(np.float64)
    counters = np.where(found, counter[at], -1).astype(np.int64)
    news = (found & new[at]).astype(bool)
    return (times, counters, news), (float(start[-1]), int(counter[-1]), bool(new[-1]),
                                     float(t_pose[-1]))


def status_before(frames: FrameArrays, decoder: BulkDecoder, positions: npt.NDArray[np.int64],
                  carried: tuple[float, int] | None = None
                  ) -> tuple[Latest, tuple[float, int] | None]:
    """For the frames at ``positions`` (in order) the latest ODOM_STATUS frame (any page) before
    each whose CRC holds (bus time, COUNTER; NaN, -1 where none; ``carried``: the latest of the
    frames before ``frames``), and the latest of all (the next chunk's ``carried``)."""
    where, t_status, counter = _rows(frames, decoder, STATUS_MESSAGE)
    if carried is not None:
        where = np.concatenate(([-1], where))
        t_status = np.concatenate(([carried[0]], t_status))
        counter = np.concatenate(([carried[1]], counter))
    if len(where) == 0:
        return (np.full(len(positions), math.nan), np.full(len(positions), -1, np.int64)), None
    k = np.searchsorted(where, positions) - 1  # the latest strictly before each
    found = k >= 0
    at = np.maximum(k, 0)
    times = np.where(found, t_status[at], math.nan).astype(np.float64)
    counters = np.where(found, counter[at], -1).astype(np.int64)
    return (times, counters), (float(t_status[-1]), int(counter[-1]))


def _run_starts(t_pose: npt.NDArray[np.float64], counter: npt.NDArray[np.int64],
                carried: tuple[float, bool] | None, first_new: bool = True
                ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
    """``next_run``'s start (bus time s, NaN: none) and whether it broke the sequence, after
    each pose row at once; ``carried``: the first row is a run carried in, its (start, broke)
    (None: not); ``first_new``: whether the first row, with no pose before, breaks it."""
    n = len(counter)
    rows = np.arange(n)
    stepped_on = np.zeros(n, dtype=bool)
    stepped_on[1:] = counter[1:] > counter[:-1]
    anchor = (counter == 0) | ~stepped_on  # where a run starts or breaks
    anchor[0] = True
    new = np.ones(n, dtype=bool)  # a COUNTER 0 that breaks the sequence of the pose before
    new[1:] = ((counter[:-1] != 0)  # a repeat is no break (``REPEAT_NO_BREAK``)
               & (t_pose[1:] - t_pose[:-1]
                  < (POSE_COUNTER_LAP - counter[:-1]) * POSE_PERIOD_S - SEQUENCE_SLACK_S))
    new[0] = first_new
    value = np.where(counter == 0, t_pose, math.nan)
    broke = (counter == 0) & new
    if carried is not None:
        value[0], broke[0] = carried
    last = np.maximum.accumulate(np.where(anchor, rows, 0))
    return value[last].astype(np.float64), broke[last].astype(bool)


def _rows(frames: FrameArrays, decoder: BulkDecoder, name: str
          ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """Positions, bus times and E2E COUNTERs of the frames of message ``name`` whose CRC holds
    (whatever their sequence: a rebooted firmware restarts it); empty without them."""
    try:
        message = decoder.message(name)
        rows = decoder.select(frames, name)
    except (DecodeError, KeyError):
        return np.zeros(0, np.int64), np.zeros(0, np.float64), np.zeros(0, np.int64)
    rows = np.asarray(rows, dtype=np.int64)
    data = frames.data[rows]
    config = e2e_messages(decoder.db).get(message.frame_id)
    good = np.ones(len(rows), dtype=bool)
    if config is not None and config.data_ids is not None:
        ids = np.array(config.data_ids, dtype=np.uint8)[data[:, 1] & ENC_COUNTER_MASK]
        good = crc8h2f_p02(data, ids) == data[:, 0]
    return (rows[good], frames.timestamp_s[rows[good]].astype(np.float64),
            (data[good, 1] & ENC_COUNTER_MASK).astype(np.int64))


def pose_rows(frames: FrameArrays, decoder: BulkDecoder
              ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """Positions, bus times and E2E COUNTERs of the ODOM_POSE_X frames of ``frames`` whose CRC
    holds (whatever their sequence); empty without them."""
    return _rows(frames, decoder, POSE_MESSAGE)


def status_rows(frames: FrameArrays, decoder: BulkDecoder
                ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """``pose_rows`` of ODOM_STATUS (any page)."""
    return _rows(frames, decoder, STATUS_MESSAGE)


def pose_heard(data: bytes, data_ids: tuple[int, ...] | None) -> int | None:
    """The E2E COUNTER of an ODOM_POSE_X frame heard live whose CRC holds, whatever its
    sequence (``data_ids``: the message's E2E DataIDs; None: no E2E); None otherwise."""
    if len(data) != 8:
        return None
    if data_ids and data[0] != crc8h2f_p02_one(data, data_ids[data[1] & ENC_COUNTER_MASK]):
        return None
    return data[1] & ENC_COUNTER_MASK
