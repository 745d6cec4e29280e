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
APPLY_FIELD = 15  # ODOM_CONFIG PARAM / ODOM_ACK REQUEST_FIELD of APPLY (the DBC's VAL_)
MAX_WAITING = 4  # frames of one COUNTER kept unanswered (two tools: two in flight)
COUNTER_LAP = 16  # frames of one sender before its 4-bit E2E COUNTER comes round
SAME_TICK_S = 0.005  # half the firmware's 10 ms tick: the ODOM_ACKs a new firmware sends in its
# first tick come before its boot summary, less than this before it; the old life's last ACK
# came a tick or more before (its last tick, then the reset and the boot)


class ConfigFollower:
    """The staged parameters and the pending APPLY of ODOM_CONFIG as the bus shows them."""

    def __init__(self, *, bus_order: bool = True) -> None:
        # ``bus_order``: the frames come in the order the firmware takes them (the monitor's,
        # analyze's); False for the bridge, which follows its own frames when it sends them
        self.bus_order = bus_order
        self.staged: dict[str, float] = {}  # PARAM: value (m, m/s, counts, raw enum), as ACKed
        self._staged_s: dict[str, float] = {}  # PARAM: bus time of its ACK (s)
        # by E2E COUNTER: the frames heard and not answered yet, oldest first: (PARAM, value,
        # None for APPLY or a parameter without one; the frame's number among those heard)
        self._sent: dict[int, list[tuple[str, float | None, int]]] = {}
        self._heard = 0  # ODOM_CONFIG frames heard
        self.built: Built | None = None  # the robot before the first config applied this life
        self.applied_s = -math.inf  # bus time of the latest APPLY ACKed (s)
        # not ``bus_order``: a PARAM of which two unlike frames of one COUNTER waited at its ACK
        # (two senders: the firmware took the first on the bus, which the bridge cannot tell):
        # the other frame's value; ``doubt``: those of the APPLY ACKed last, with ``applied``,
        # the staged set it returned (``host.judge.liveconfigdoubt``)
        self._doubt: dict[str, float] = {}
        self.doubt: dict[str, float] = {}
        self.applied: dict[str, float] = {}

    def forget(self, since_s: float = math.inf) -> None:
        """A firmware reboot the judge saw: the firmware lost its staged parameters with its RAM
        (a bare APPLY after it applies its build's robot again); ``since_s``: the parameters
        ACKed from this bus time on (s) are the new firmware's, kept with the frames not
        answered yet (default: none, everything forgotten)."""
        if since_s == math.inf:
            self._sent, self._doubt = {}, {}
        kept = {p for p, t_s in self._staged_s.items() if t_s >= since_s}
        self.staged = {p: v for p, v in self.staged.items() if p in kept}
        self._staged_s = {p: t_s for p, t_s in self._staged_s.items() if p in kept}

    def on_frame(self, counter: int, param: str, value: Any) -> None:
        """An ODOM_CONFIG frame heard (its E2E COUNTER, PARAM name, the value in DBC units)."""
        number = None if param not in PARAMS or value is None else float(value)
        self._heard += 1
        waiting = self._sent.setdefault(counter, [])
        # one sender's COUNTER comes round in 16 frames: a frame of it that far back was never
        # answered (the rule before: the latest of a COUNTER); two tools' are in flight at once
        waiting[:] = [w for w in waiting if self._heard - w[2] < COUNTER_LAP][-MAX_WAITING:]
        waiting.append((param, number, self._heard))

    def on_ack(self, request_counter: int, acked: bool, t_s: float = -math.inf,
               request_field: int | None = None) -> dict[str, float] | None:
        """ODOM_ACK of an ODOM_CONFIG frame (heard at bus time ``t_s``, s; its REQUEST_FIELD,
        None: unknown): a parameter ACKed is staged; the APPLY's ACK returns the staged set
        (None when NACKed) and clears it, as the firmware does. The frame it answers: the
        oldest of its COUNTER not answered yet whose PARAM is the REQUEST_FIELD (the firmware
        answers in bus order; those of the COUNTER before it were never answered). Two tools
        on ODOM_CONFIG (``host.judge.twosenders``) put two frames of one COUNTER in flight:
        the latest of a COUNTER (the rule before) took a frame the ACK did not answer, and the
        monitor FAILed a correct firmware with the other tool's wheelbase."""
        frame = self._answered(request_counter, request_field)
        if frame is None:
            return None
        param, value, _ = frame
        if param != "APPLY":
            if acked and param in PARAMS and value is not None:
                self.staged[param] = value
                self._staged_s[param] = t_s
                self._doubted(request_counter, param, value)
            return None
        staged, self.staged, self._staged_s = self.staged, {}, {}
        doubt, self._doubt = self._doubt, {}
        if acked:
            self.applied_s, self.applied = t_s, staged
            self.doubt = {p: v for p, v in doubt.items() if p in staged}
        return staged if acked else None

    def _doubted(self, counter: int, param: str, value: float) -> None:
        """Not ``bus_order``: ``param`` staged with ``value`` while another frame of its
        COUNTER and PARAM with another value waits: which of the two the firmware took is not
        known (``doubt``)."""
        if self.bus_order:
            return
        others = [w[1] for w in self._sent.get(counter, [])
                  if w[0] == param and w[1] is not None and w[1] != value]
        if others:
            self._doubt[param] = others[0]
        else:
            self._doubt.pop(param, None)

    def _answered(self, counter: int, field: int | None
                  ) -> tuple[str, float | None, int] | None:
        """The frame an ODOM_ACK of ``counter`` and REQUEST_FIELD ``field`` answers, taken out
        with those of its COUNTER heard before it when the frames come in ``bus_order``
        (``on_ack``; else it alone); None when none waits."""
        waiting = self._sent.get(counter, [])
        name = None if field is None else field_name(field)
        at = next((k for k, w in enumerate(waiting) if name in (None, w[0])), None)
        if at is None:
            return None
        frame = waiting[at]
        if self.bus_order:
            del waiting[:at + 1]
        else:
            del waiting[at]
        return frame


def field_name(field: int) -> str:
    """ODOM_ACK REQUEST_FIELD of an ODOM_CONFIG frame -> its PARAM name (the DBC's VAL_)."""
    if field == APPLY_FIELD:
        return "APPLY"
    return PARAMS[field] if 0 <= field < len(PARAMS) else str(field)


Built = tuple[Geometry, int, int, str | None]  # geometry, its counter width (the tracker's,
# the distance judge's) and integrator: the judges' robot before a config applied


class Judges(Protocol):
    """The live judges an applied config reconfigures (the monitor's, a bridge robot's)."""

    tracker: PoseTracker
    distance: LiveDistance
    twist: LiveTwist
    events: deque[dict[str, Any]]


def follow_config_ack(judges: Judges, follower: ConfigFollower, request_counter: int,
                      acked: bool, t_s: float, request_field: int | None = None) -> bool:
    """ODOM_ACK of an ODOM_CONFIG frame (its REQUEST_COUNTER; ``acked``: RESULT 0) heard at
    bus time ``t_s`` (s): an ACKed APPLY makes the staged set ``judges``' robot (reference,
    DISTANCE and speed judges, from here as a new life) and a ``config`` event. Returns
    whether a config was applied."""
    config = follower.on_ack(request_counter, acked, t_s, request_field)
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


def staged_geometry(g: Geometry, staged: dict[str, float]) -> Geometry:
    """``g`` overwritten by the parameters of ``staged`` (an applied config)."""
    speed = staged.get("MAX_WHEEL_SPEED")
    return Geometry(
        int(staged.get("COUNTS_PER_REV", g.counts_per_rev)),
        staged.get("WHEEL_RADIUS_LEFT", g.wheel_radius_left_m),
        staged.get("WHEEL_RADIUS_RIGHT", g.wheel_radius_right_m),
        staged.get("WHEELBASE", g.wheelbase_m),
        g.max_wheel_speed_mm_s if speed is None else round(speed * 1000),
    )


def apply_config(tracker: PoseTracker, staged: dict[str, float]) -> str:
    """Make ``staged`` (an applied config) ``tracker``'s robot, the parameters it lacks kept;
    the reference restarts at the next on-board pose. Returns the event's detail."""
    geometry = staged_geometry(tracker.geometry, staged)
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
