"""ODOM_CONFIG followed by the live judges (``odocan monitor`` and the bridge's
``host.mqtt.telemetry``, both through ``follow_config_ack``): an applied config is the
firmware's new robot, so it is the reference's too, whoever sent it (the bridge's own config
command, the ``odocan`` CLI, a user's script on the same bus).

The firmware (firmware/commands.py) stages each parameter frame it accepted (ACK), and APPLY
validates its current parameters overwritten by the staged ones, all or nothing (ACK, or NACK
with the reason), and clears the staged set either way. So ``ConfigFollower`` stages a parameter
when its ACK is heard, and the APPLY's ACK returns the staged set (``apply_config`` makes it the
tracker's geometry, integrator and counter width; the reference restarts at the next on-board
pose). A NACKed APPLY changes nothing: the firmware keeps its parameters. Found by the trial: the
monitor restarted its reference at every APPLY heard but kept the old parameters, so after an
accepted config (kobuki, wheelbase 0.23 -> 0.25 m) it said POSE WRONG, 938 mm, exit 1, while the
firmware was right with its new wheelbase. The bridge took the parameters of its own config
command at its APPLY's ACK: it kept the old robot when another tool configured the firmware
(a correct firmware failed, one that ACKed but kept its wheelbase passed), and after a reboot
between its pages and its APPLY it took the parameters the new firmware never staged.
"""

from __future__ import annotations

import math
from collections import deque
from typing import TYPE_CHECKING, Any, Protocol

from odocan.host.judge.reference import Geometry

if TYPE_CHECKING:
    from odocan.host.judge.livedistance import LiveDistance
    from odocan.host.judge.livetwist import LiveTwist
    from odocan.host.judge.tracking import PoseTracker

PARAMS = ("COUNTS_PER_REV", "WHEEL_RADIUS_LEFT", "WHEEL_RADIUS_RIGHT", "WHEELBASE", "COUNTER_BITS",
          "INTEGRATOR", "MAX_WHEEL_SPEED")  # ODOM_CONFIG's staged PARAMs (names in the DBC)
INTEGRATORS = ("euler", "rk2", "exact")  # INTEGRATOR's raw values 0, 1, 2
SAME_TICK_S = 0.005  # half the firmware's 10 ms tick: the ODOM_ACKs a new firmware sends in its
# first tick come before its boot summary, less than this before it; the old life's last ACK
# came a tick or more before (its last tick, then the reset and the boot)


class ConfigFollower:
    """The staged parameters and the pending APPLY of ODOM_CONFIG as the bus shows them."""

    def __init__(self) -> None:
        self.staged: dict[str, float] = {}  # PARAM: value (m, m/s, counts, raw enum), as ACKed
        self._staged_s: dict[str, float] = {}  # PARAM: bus time of its ACK (s)
        self._sent: dict[int, tuple[str, float]] = {}  # by E2E COUNTER: PARAM, value heard
        self._applies: set[int] = set()  # the COUNTERs of the APPLY frames not answered yet
        self.built: Built | None = None  # the robot before the first config applied this life
        self.applied_s = -math.inf  # bus time of the latest APPLY ACKed (s)

    def forget(self, since_s: float = math.inf) -> None:
        """A firmware reboot the judge saw: the firmware lost its staged parameters with its RAM
        (a bare APPLY after it applies its build's robot again); ``since_s``: the parameters
        ACKed from this bus time on (s) are the new firmware's, kept with the frames not
        answered yet (default: none, everything forgotten)."""
        if since_s == math.inf:
            self._sent, self._applies = {}, set()
        kept = {p for p, t_s in self._staged_s.items() if t_s >= since_s}
        self.staged = {p: v for p, v in self.staged.items() if p in kept}
        self._staged_s = {p: t_s for p, t_s in self._staged_s.items() if p in kept}

    def on_frame(self, counter: int, param: str, value: Any) -> None:
        """An ODOM_CONFIG frame heard (its E2E COUNTER, PARAM name, the value in DBC units)."""
        self._sent.pop(counter, None)  # the latest frame of a COUNTER is the one its ACK answers
        self._applies.discard(counter)
        if param == "APPLY":
            self._applies.add(counter)  # several: two configs back to back, each APPLY its ACK
        elif param in PARAMS and value is not None:
            self._sent[counter] = (param, float(value))

    def on_ack(self, request_counter: int, acked: bool, t_s: float = -math.inf
               ) -> dict[str, float] | None:
        """ODOM_ACK of an ODOM_CONFIG frame (heard at bus time ``t_s``, s): a parameter ACKed
        is staged; the APPLY's ACK returns the staged set (None when NACKed) and clears it, as
        the firmware does."""
        sent = self._sent.pop(request_counter, None)
        if sent is not None:
            if acked:
                self.staged[sent[0]] = sent[1]
                self._staged_s[sent[0]] = t_s
            return None
        if request_counter not in self._applies:
            return None
        self._applies.discard(request_counter)
        staged, self.staged, self._staged_s = self.staged, {}, {}
        if acked:
            self.applied_s = t_s
        return staged if acked else None


Built = tuple[Geometry, int, int, str | None]  # geometry, its counter width (the tracker's,
# the distance judge's) and integrator: the judges' robot before a config applied


class Judges(Protocol):
    """The live judges an applied config reconfigures (the monitor's, a bridge robot's)."""

    tracker: PoseTracker
    distance: LiveDistance
    twist: LiveTwist
    events: deque[dict[str, Any]]


def follow_config_ack(judges: Judges, follower: ConfigFollower, request_counter: int,
                      acked: bool, t_s: float) -> bool:
    """ODOM_ACK of an ODOM_CONFIG frame (its REQUEST_COUNTER; ``acked``: RESULT 0) heard at
    bus time ``t_s`` (s): an ACKed APPLY makes the staged set ``judges``' robot (reference,
    DISTANCE and speed judges, from here as a new life) and a ``config`` event. Returns
    whether a config was applied."""
    config = follower.on_ack(request_counter, acked, t_s)
    if config is None:
        return False
    tracker = judges.tracker
    if follower.built is None:  # the firmware's build's robot, back at its next reboot
        follower.built = (tracker.geometry, tracker.counter_bits,
                          judges.distance.robot.counter_bits, tracker.integrator)
    detail = apply_config(tracker, config)
    geometry = judges.tracker.geometry
    counter_bits = int(config.get("COUNTER_BITS", judges.distance.robot.counter_bits))
    judges.distance.reconfigure(geometry, counter_bits)  # the width as configured (its CRC)
    judges.twist.reconfigure(geometry, counter_bits)
    judges.events.append({"t_s": t_s, "kind": "config", "detail": detail})
    return True


def rebooted(judges: Judges, follower: ConfigFollower, t_s: float) -> str | None:
    """A firmware reboot the judges saw (call before they start its new life): its staging
    and the configs it applied were in its RAM, so it comes up with its build's robot, and the
    judges take back the robot they had before the first config applied (``analyze`` judges
    the lives after a reboot with the log's robot likewise, ``host.judge.configs``). Found by
    the trial: after a config the firmware applied (wheelbase 0.23 -> 0.25 m) and a reboot,
    the bridge judged the new life with 0.25 m: POSE WRONG (53 mm) on a correct firmware
    running its build's 0.23 m. ``t_s``: the bus time of the boot summary that told it (s);
    what was ACKed less than ``SAME_TICK_S`` before is the new firmware's (its first tick), kept.
    Returns the ``config`` event's detail (None: none applied, or in the new firmware)."""
    since_s = t_s - SAME_TICK_S
    follower.forget(since_s)
    if follower.applied_s >= since_s:  # applied by the new firmware: its robot now
        return None
    built, follower.built = follower.built, None
    if built is None:
        return None
    geometry, counter_bits, distance_bits, integrator = built
    tracker = judges.tracker
    tracker.integrator = integrator
    tracker.set_geometry(geometry, counter_bits)
    judges.distance.reconfigure(geometry, distance_bits)
    judges.twist.reconfigure(geometry, distance_bits)
    return config_text(geometry.counts_per_rev, geometry.wheel_radius_left_m,
                       geometry.wheel_radius_right_m, geometry.wheelbase_m, integrator,
                       lead="config lost with the reboot, the build's robot again")


def apply_config(tracker: PoseTracker, staged: dict[str, float]) -> str:
    """Make ``staged`` (an applied config) ``tracker``'s robot, the parameters it lacks kept;
    the reference restarts at the next on-board pose. Returns the event's detail."""
    g = tracker.geometry
    speed = staged.get("MAX_WHEEL_SPEED")
    geometry = Geometry(
        int(staged.get("COUNTS_PER_REV", g.counts_per_rev)),
        staged.get("WHEEL_RADIUS_LEFT", g.wheel_radius_left_m),
        staged.get("WHEEL_RADIUS_RIGHT", g.wheel_radius_right_m),
        staged.get("WHEELBASE", g.wheelbase_m),
        g.max_wheel_speed_mm_s if speed is None else round(speed * 1000),
    )
    if "INTEGRATOR" in staged and 0 <= int(staged["INTEGRATOR"]) < len(INTEGRATORS):
        tracker.integrator = INTEGRATORS[int(staged["INTEGRATOR"])]
    tracker.set_geometry(geometry, int(staged.get("COUNTER_BITS", tracker.counter_bits)))
    return config_text(geometry.counts_per_rev, geometry.wheel_radius_left_m,
                       geometry.wheel_radius_right_m, geometry.wheelbase_m, tracker.integrator)


def config_text(counts_per_rev: int, wheel_radius_left_m: float, wheel_radius_right_m: float,
                wheelbase_m: float, integrator: str | None, *, lead: str = "config applied") -> str:
    """The ``config`` event's words (the monitor's and ``analyze``'s, host.judge.configs)."""
    return (f"{lead}: {counts_per_rev} counts/rev, wheel radii "
            f"{wheel_radius_left_m:.6g}/{wheel_radius_right_m:.6g} m, wheelbase "
            f"{wheelbase_m:.6g} m, {integrator}: reference restarted")
