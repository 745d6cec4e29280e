"""The live judges' boot tick (issue #11: "a FAIL must never blame a correct firmware"): the
encoder frame a rebooted firmware primed on, when the host's own E2E check refused it.

The host checks WHEEL_ENCODERS with one sequence run on across a reboot (the motor controller
did not reboot); the new firmware's receiver starts fresh at its first tick. A delay that
reordered a frame of the boot made the host's sequence refuse the frames after it until it
resynchronised, while the new firmware, booted after the reorder, primed on one of them and
took the next: kobuki ``--seed 1 --faults delay=0.1:15,reboot=10:0.3``, COUNTER 6 at 10.30 s
(the boot summary at 10.301 s). The live window held only the frames the host's sequence took
(COUNTER 2 at 10.275 s, then COUNTER 8 at 10.32 s), so neither the first count page
(``livewindow.primed_at``) nor the summary's rule could name it: the correct firmware FAILed
5.89 mm, 11.5 mrad off, which ``analyze`` PASSes (``silentboot.fresh_counted_start``: the boot
summary's frame, its E2E check fresh there).

Now the summary's frame (the latest encoder frame heard before the boot summary of UPTIME 0,
not INIT, less than a cycle before it), refused with its CRC right, is taken into the window as
the new firmware took it, and the host's sequence restarts at it as the firmware's did
(``E2EMonitor.retake``, its counts unchanged): the frames after it are judged as the new
firmware judged them, and the first count page names it by the window's own rule. Not taken:
a frame whose COUNTER goes back from the latest taken, that one heard in the summary's tick too
(a late frame the firmware drained after a newer one it primed on), nor a repeat less than half
a COUNTER lap after it (a twin, ``livetwins``, or the frame again). The latest taken heard a
cycle or more before a summary not held back (its bus time its tick's) came before the new
firmware's first drain: it primed on the late frame (pmir and kobuki random 2
``reboot=3:0.1,delay=0.3:55``: COUNTER 0 sent at 3.04 s, held back to 3.095 s, after the
on-time COUNTER 4 of 3.08 s; the page OK 6, LOST 5 then counted back a lap early, 20.9-23.9 mm
and 119-156 mrad beyond; ``tests/test_live_reboot_late_primed.py``)."""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from odocan.host.judge.bootnamed import HELD_WINDOW_S
from odocan.host.judge.livefreshboot import TWIN_S, init_restart
from odocan.host.judge.livelatehalves import LATE_NAMES
from odocan.host.judge.livetwins import refused_encoders
from odocan.host.judge.livewindow import CYCLE_S, HALF_LAP
from odocan.host.judge.swappedskips import LATE_BEHIND
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK
from odocan.host.protocol.e2e import REPEATED, WRONG_SEQUENCE

LATE_KEPT = 256  # late frames refused kept for the DISTANCE judge's next page (liveskip)

if TYPE_CHECKING:
    from odocan.host.judge.tracking import PoseTracker
    from odocan.host.protocol.e2e_live import E2EMonitor

RECENT_REFUSED = 8  # refused frames kept (``BootTick.recent``)
Frame = tuple[int, int, int, float, int]  # COUNTER, LEFT_COUNT, RIGHT_COUNT, bus time s, uptime


class BootTick:
    """The latest WHEEL_ENCODERS frame refused with its CRC right (``frame``, its E2E
    ``status``), while no encoder frame was accepted after it (``PoseTracker.on_encoders``
    forgets it)."""

    frame: Frame | None
    status: str
    can_id: int

    def __init__(self) -> None:
        self.frame = None
        self.status = ""
        self.can_id = -1
        self.behind = False  # ``frame`` kept behind frames taken after it (``taken``)
        # the latest refused, each with the seq of the latest frame taken before it
        # (``liveheldstart``: a held summary's tick may have primed on one)
        self.recent: deque[tuple[Frame, int]] = deque(maxlen=RECENT_REFUSED)
        # the judge's E2E check and encoder handler (``bind``; ``livefreshboot``)
        self.bound: tuple[E2EMonitor, Callable[[tuple[int, int, int, int], float], object]] \
            | None = None

    def bind(self, e2e: E2EMonitor,
             take: Callable[[tuple[int, int, int, int], float], object]) -> None:
        """The judge's E2E check and its WHEEL_ENCODERS handler (as ``boot_frame``'s)."""
        self.bound = (e2e, take)

    def refused(self, can_id: int, signals: Any, t_s: float, status: str,
                after: int = -1) -> None:
        """A WHEEL_ENCODERS frame (identifier ``can_id``, 11-bit) refused (``signals``: its raw
        signals, a mapping) at bus time ``t_s``, by ``status``; ``after``: the seq of the
        latest frame taken before it."""
        self.can_id = can_id
        self.frame = (int(signals["COUNTER"]), int(signals["LEFT_COUNT"]),
                      int(signals["RIGHT_COUNT"]), t_s, int(signals.get("CTRL_UPTIME", 0)))
        self.recent.append((self.frame, after))
        self.status = status
        self.behind = False

    def taken(self, counter: int, t_s: float) -> None:
        """A WHEEL_ENCODERS frame of COUNTER ``counter`` taken at bus time ``t_s``: the refused
        frame is forgotten, unless the taken one goes back from it less than a cycle after it
        (a late frame, which a new firmware primed on the refused one refuses as old: kobuki
        random 696 ``reboot=0.2:0.2,delay=0.1:150``, the power-up pose naming COUNTER 9 at
        0.401 s, the host's sequence having taken COUNTER 8 after it); kept ``behind`` them for
        the power-up pose's rule alone (``livefreshboot``), not the summary's."""
        frame = self.frame
        if frame is not None and t_s - frame[3] < CYCLE_S \
                and (counter - frame[0]) & ENC_COUNTER_MASK >= HALF_LAP:
            self.behind = True
            return
        self.frame, self.behind = None, False


def boot_frame(tracker: PoseTracker, e2e: E2EMonitor, told: tuple[int, str, int | None, float],
               take: Callable[[tuple[int, int, int, int], float], object],
               held_tick_s: float | None = None) -> Frame | None:
    """The refused encoder frame the firmware booted by the summary heard now primed on
    (module docstring; ``told``: the summary's UPTIME s, STATE, the latest encoder frame at it
    when the reboot was told after it, and its bus time s), the host's WHEEL_ENCODERS
    sequence restarted at it, and given to ``take`` as an accepted frame (the judges'
    WHEEL_ENCODERS handler: COUNTER, LEFT_COUNT, RIGHT_COUNT, CTRL_UPTIME; bus time s). None
    when the summary's rule names an accepted frame (or none). ``held_tick_s``: the summary was
    held back past its tick (``sources.SourceWatch.held_tick_s``): its bus time tells no drain,
    a late frame is not taken."""
    uptime_s, state, seq, t_s = told
    tick = tracker.boot_tick
    frame, tick.frame = (None if tick.behind else tick.frame), None
    init_restart(e2e, (uptime_s, state, seq))  # primes on the next (livefreshboot)
    if frame is None or uptime_s != 0 or state == "INIT" or seq is not None:
        return None
    if t_s - frame[3] >= CYCLE_S:  # not the summary's tick's frame
        return None
    if tick.status not in (REPEATED, WRONG_SEQUENCE) or _pose_retook(tracker, e2e, t_s):
        return None
    rows = tracker.window.rows
    step = (frame[0] - int(rows[-1][2])) & ENC_COUNTER_MASK if rows else 1
    late = step >= HALF_LAP and (  # the newer one drained first (the module docstring)
        held_tick_s is not None or t_s - rows[-1][3] < CYCLE_S)
    if late or (step == 0 and frame[3] - rows[-1][3] < TWIN_S):
        return None  # a late frame after one of the tick (drained first), a twin, the same
    e2e.retake(tick.can_id, frame[0], frame[3])
    take((frame[0], frame[1], frame[2], frame[4]), frame[3])
    return frame


def _pose_retook(tracker: PoseTracker, e2e: E2EMonitor, t_s: float) -> bool:
    """Whether a power-up pose heard less than ``HELD_WINDOW_S`` before the summary heard at
    bus time ``t_s`` retook the frame it named (heard less than a cycle before the pose: the
    latest ``E2EMonitor.retake``), after the host's sequence refused it
    (``livefreshboot``): the life's frame is named, the summary's is not the new firmware's
    first (kobuki random 908, ``reboot=1.5:0.3,delay=0.1:200``: the power-up pose of 1.801 s
    retook the COUNTER 0 held back to 1.800 s; the boot summary of 1.901 s retook the
    on-time COUNTER 14 of 1.90 s, which the firmware refused)."""
    pose, retaken = tracker.powerup.latest, e2e.retaken
    return (pose is not None and retaken is not None and pose[1] is not None
            and 0.0 <= t_s - pose[0] < HELD_WINDOW_S and 0.0 <= pose[0] - retaken[2] < CYCLE_S)


def refused_frame(tracker: PoseTracker, can_id: int, signals: Any, t_s: float,
                  status: str) -> None:
    """A WHEEL_ENCODERS frame (11-bit ``can_id``) E2E refused (``status``) with its CRC right,
    decoded (``signals``: a mapping of its raw signals), heard at bus time ``t_s``: to the twins
    and a gap's fill (``livetwins.refused_encoders``) and to ``tracker.boot_tick``. A late one
    (behind the latest taken) within a lock-out after the firmware resumed from an MCU halt
    (``E2EMonitor.after_halt``) widens the DISTANCE judge's next span (``tracker.late_refused``,
    ``liveskip``, as the trial36 stall drives need): widening by every late one refused PASSed
    a DISTANCE 2 mm low under capture jitter with no halt (test_live_jitter_skipped_distance)."""
    refused_encoders(tracker.twins, signals, t_s, tracker.placer.fill)
    tracker.boot_tick.refused(can_id, signals, t_s, status, tracker.enc_seq)
    rows, bound = tracker.window.rows, tracker.boot_tick.bound
    if rows and bound is not None and bound[0].after_halt(t_s) \
            and 1 <= (int(rows[-1][2]) - int(signals["COUNTER"])) & ENC_COUNTER_MASK <= LATE_BEHIND:
        tracker.late_refused.append(tracker.enc_seq + 1)  # swappedskips.late (liveskip)
        del tracker.late_refused[:-LATE_KEPT]  # no page to drop them: bounded


def refused_named(tracker: PoseTracker, can_id: int, name: str, signals: Callable[[], Any],
                  t_s: float, status: str) -> None:
    """A frame of message ``name`` E2E refused (``status``) with its CRC right, heard at bus
    time ``t_s``: a WHEEL_ENCODERS frame to ``refused_frame`` (``signals``: its raw signals,
    decoded when asked), an ODOM_POSE_Y counted as sent (``livestall.StallRule.pose_refused``:
    the hold evidence's quiet); a pose half or twist read in its sender's sequence
    (``livelatehalves``)."""
    if name == "WHEEL_ENCODERS":
        refused_frame(tracker, can_id, signals(), t_s, status)
        return
    if name in LATE_NAMES:
        tracker.late.refused(name, t_s, int(signals()["COUNTER"]))
    if name == "ODOM_POSE_Y":
        tracker.stall.pose_refused(t_s)
