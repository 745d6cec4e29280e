"""The live judges' WHEEL_ENCODERS check restarted where a rebooted firmware's started (issue
#11: "a FAIL must never blame a correct firmware").

``analyze`` (whole and streamed) checks each firmware life's E2E afresh from the encoder frame
its firmware primed on (``host.judge.reboots``); the live judges (monitor, bridge) keep one host
sequence for the motor controller, which did not reboot. Under a bus that held frames back
(``delay=0.3:55``), a new firmware may prime on an old frame the host's sequence refused, then
take the late run after it and refuse the on-time frames the host's sequence took: the live
window held none of the frames it integrated, its first count page named none, and the life
started on a guess (kobuki and pmir figure8 671, 673, 677, 678, 680 under
``reboot=1.8:0.2,stall=5.6:0.2,delay=0.3:55``: 16-64 mm beyond the allowance while run and both
analyses PASSed). Two rules, the frame each names the one ``analyze``'s split starts the life at:

* a boot summary of UPTIME 0 and STATE INIT (no encoder frame taken yet), told at its own
  frame: the firmware primes on the next encoder frame, whatever the host's sequence says of
  it; the host's sequence restarts there (``init_restart``);
* a power-up pose (COUNTER 0, X 0, HEADING 0) naming by its ENC_COUNTER the latest encoder
  frame heard, refused with its CRC right less than a cycle before it (while no frame was taken
  after it): the firmware primed on it (``bootnamed``); the host's sequence restarts at it and
  it is taken as the firmware took it (``powerup_heard``), as ``liveboottick`` takes a boot
  summary's frame. Not a twin of the latest frame taken (the pose names that one).

From there the host's sequence judges the frames as the new firmware's fresh one did."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from odocan.host.judge.bootnamed import is_powerup_pose
from odocan.host.judge.livewindow import CYCLE_S, HALF_LAP
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.protocol.e2e import REPEATED, WRONG_SEQUENCE

if TYPE_CHECKING:
    from odocan.host.judge.tracking import PoseTracker
    from odocan.host.protocol.e2e_live import E2EMonitor

TWIN_S = HALF_LAP * CYCLE_S  # a repeat nearer than this to the frame it repeats: a twin
ENCODER_ID = default_plan().get_message_by_name("WHEEL_ENCODERS").frame_id  # this DBC's


def init_restart(e2e: E2EMonitor, told: tuple[int, str, int | None]) -> None:
    """A reboot told by its boot summary (``told``: UPTIME s, STATE, the latest encoder frame
    when told after it): of UPTIME 0 and STATE INIT, told at it, the host's WHEEL_ENCODERS
    sequence starts afresh at the next frame, as the firmware's did."""
    uptime_s, state, seq = told
    if uptime_s == 0 and state == "INIT" and seq is None:
        e2e.restart_sequence(ENCODER_ID)


def powerup_heard(tracker: PoseTracker, counter: int, signals: Callable[[], Any],
               t_s: float) -> None:
    """Any ODOM_POSE_X whose CRC holds (E2E ``counter``, ``signals()``: its decoded signals)
    heard at bus time ``t_s``: a power-up pose naming a refused frame retakes it (module
    docstring), then to the tracker's power-up poses (``bootnamed.LivePowerUp.on_pose``)."""
    if counter == 0:
        _retake_named(tracker, signals(), t_s)
        tracker.powerpose.heard_x(signals(), t_s, tracker)  # the E2E check may refuse it
    tracker.powerup.on_pose(counter, signals, t_s, tracker.window.rows)
    tracker.lives.silent.heard(t_s, signals, tracker.window.rows)  # (livesilentboot)


def _retake_named(tracker: PoseTracker, s: Any, t_s: float) -> None:
    """The refused frame the power-up pose ``s`` heard at ``t_s`` names, taken (docstring)."""
    tick = tracker.boot_tick
    frame, bound = tick.frame, tick.bound
    if bound is None or not is_powerup_pose(int(s["COUNTER"]), s["X"], s["HEADING"]):
        return
    if frame is None or tick.status not in (REPEATED, WRONG_SEQUENCE):
        _retake_in_tick(tracker, int(s["ENC_COUNTER"]), t_s)
        return
    if int(s["ENC_COUNTER"]) != frame[0] or not 0.0 <= t_s - frame[3] < CYCLE_S:
        return
    rows = tracker.window.rows
    if rows and int(rows[-1][2]) == frame[0] and frame[3] - rows[-1][3] < TWIN_S:
        return  # a twin of the latest taken: the pose names that one
    e2e, take = bound
    tick.frame = None
    e2e.retake(tick.can_id, frame[0], frame[3])
    take((frame[0], frame[1], frame[2], frame[4]), frame[3])
    tracker.late.restart()  # its pose sequences start at this pose (livelatehalves)


def _retake_in_tick(tracker: PoseTracker, enc_counter: int, t_s: float) -> None:
    """``bootnamed.heard_named`` live: the power-up pose heard at bus time ``t_s`` names
    COUNTER ``enc_counter``; no frame of it taken less than a cycle before the pose, the latest
    refused one of it heard there with its CRC right (``BootTick.recent``), after the latest
    taken of it, is the frame the new firmware primed on, though the host's sequence took a
    frame after it: the firmware's receiver, fresh, drained it first and refused the next
    (issue #11: kobuki random 908, ``reboot=1.5:0.3,delay=0.1:200``, primed at 1.80 s on a
    COUNTER 0 sent at 1.60 s; the host's sequence refused it and took COUNTER 4 of 1.800 s;
    the on-time COUNTER 0 of 1.76 s, heard in the boot, was named: 35-53 mm beyond)."""
    rows, tick = tracker.window.rows, tracker.boot_tick
    if not rows or tick.bound is None:
        return
    taken = [row for row in rows if int(row[2]) == enc_counter]
    if taken and t_s - float(taken[-1][3]) < CYCLE_S:
        return  # one taken in the pose's tick: the pose names it
    after = int(taken[-1][0]) if taken else -1
    mine = [frame for frame, seq in tick.recent if frame[0] == enc_counter and seq >= after
            and 0.0 <= t_s - frame[3] < CYCLE_S]
    if not mine:
        return
    frame = mine[-1]
    e2e, take = tick.bound
    e2e.retake(tick.can_id, frame[0], frame[3])
    take((frame[0], frame[1], frame[2], frame[4]), frame[3])
    tracker.late.restart()  # its pose sequences start at this pose (livelatehalves)
