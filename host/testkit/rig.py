"""A test driver for odometry firmware on a CAN bus: what the pytest fixture ``odocan_rig`` returns.

``OdocanRig`` puts a firmware under test and lets a test drive it and judge it from the bus only:

* **drive**: an open-loop scenario (``drive``), navigation goals for the firmware's own
  controller (``goto``, ``path``, ``run_until_reached``), or just time (``step``, ``run_until``);
* **read**: every frame the host heard, decoded by cantools from the DBC after its E2E check
  (``frames``, ``latest``, ``nav_status``, ``odom_status``), the on-board ``pose``, the ground
  ``truth``, the float64 ``reference`` and the analysis ``report`` (``host.analysis``);
* **judge**: ``assert_pose_matches_reference``, ``assert_near_truth``, ``assert_reached`` raise an
  ``AssertionError`` whose message carries the numbers.

Two backends run the same API:

* ``LockstepBackend``: our firmware in a ``sim.rig.LockstepRig`` (closed loop, simulated time, on a
  python-can ``virtual`` channel of its own): ``step`` computes, deterministic for a seed.
* ``ExternalBackend``: ANY firmware that speaks the DBC, already running on a real bus
  (``udp_multicast``, ``socketcan``, ...). The backend plays the rest of the robot in real time in a
  thread (``sim.motor_controller.SimNode``: the motor controller, the SIM truth and the scenario
  driver, every 10 ms of the wall clock) and a host handle hears every frame:
  ``step`` sleeps. On attaching, the rig configures the firmware for the robot and integrator over
  ODOM_CONFIG, puts its pose at the origin with ODOM_SET_POSE (where the new simulated robot
  stands), waits for STATE OK, and only then starts recording.

Times (``timestamp_s``, ``now_s``) are seconds since the recording started: simulated seconds in
lockstep, wall-clock seconds on a real bus.
"""

from __future__ import annotations

import itertools
import json
import math
import queue
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple, Protocol

import can
import cantools
from cantools.database.namedsignalvalue import NamedSignalValue

from odocan.host.io.buses import isolated_bus_kwargs
from odocan.host.io.logs import FrameArrays, FrameCollector
from odocan.host.judge.analysis import HEADING_LSB_RAD, POSITION_LSB_M, Analysis, analyze
from odocan.host.protocol.commands import Command, CommandEncoder
from odocan.host.protocol.e2e import OK, OKSOMELOST, UNPROTECTED, E2EMonitor
from odocan.sim import contract
from odocan.sim.board import TICK_S
from odocan.sim.clock import RealTimeClock
from odocan.sim.errors import ErrorModel
from odocan.sim.errors import parse as parse_errors
from odocan.sim.exceptions import BusSetupError, OdocanError
from odocan.sim.faults import FaultInjectingBus, FaultSpec
from odocan.sim.motor_controller import SimNode
from odocan.sim.realtime import PeriodicLoop
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.robot import RobotProfile
from odocan.sim.robot import load as load_robot
from odocan.sim.scenarios import Scenario, get_scenario
from odocan.sim.vehicle import Vehicle

_ACCEPTED = (OK, OKSOMELOST, UNPROTECTED)  # E2E statuses of frames a host may use
_LOCKSTEP_ACK_TIMEOUT_S = 1.0  # simulated seconds for an ODOM_ACK (it comes in the next tick)
_EXTERNAL_ACK_TIMEOUT_S = 3.0  # wall-clock seconds on a real bus
_POLL_S = 0.01  # how often a real-time wait looks at what was heard
_TRACKING_POSES = 10  # pose frames in a row that must name our encoder frames (0.2 s)
_TRACKING_WINDOW_S = 0.05  # ... one sent at most this long before the pose frame
_channels = itertools.count()


class TestkitError(OdocanError):
    """The rig cannot do what was asked (no frame yet, a firmware that does not answer, ...)."""

    __test__ = False  # not a test class, whatever pytest's collection rules say


class CommandRefused(AssertionError):
    """The firmware answered a command with ODOM_ACK NACK (or not at all)."""


class Pose(NamedTuple):
    """A pose in the odometry frame: metres and radians (heading unwrapped where it is known)."""

    x_m: float
    y_m: float
    heading_rad: float


@dataclass(frozen=True)
class RigOptions:
    """What a rig is made of (strings as on the command line: ``errors="ed=1.002"``)."""

    robot: str = "pmir"
    integrator: str = "exact"
    errors: str = ""
    faults: str = ""
    fw_faults: str = ""
    seed: int = 0

    def profile(self) -> RobotProfile:
        """The robot profile (a name or a TOML path)."""
        return load_robot(self.robot)

    def error_model(self) -> ErrorModel:
        """The simulated robot's real errors."""
        return parse_errors(self.errors)


def _fault_spec(text: str) -> FaultSpec | None:
    spec = FaultSpec.parse(text)
    return spec if spec.active else None


# --- what the host heard ----------------------------------------------------------------------


class Recorder(can.Listener):
    """Every frame heard: kept for the analysis, and decoded per message on demand.

    Thread safe: a real-time backend feeds it from its own thread. ``restamp`` (a clock) makes
    every timestamp relative to that clock, whatever time base the interface stamps with.
    """

    def __init__(
        self, db: cantools.database.can.Database, restamp: Callable[[], float] | None = None
    ) -> None:
        self.db = db
        self._restamp = restamp
        self._lock = threading.Lock()
        self._offset: float | None = None
        self.reset()

    def reset(self, origin_s: float = 0.0) -> None:
        """Forget everything heard so far: the recording starts again, at ``origin_s`` of the
        ``restamp`` clock."""
        with self._lock:
            self._origin_s = origin_s
            self._collector = FrameCollector()
            self._raw: dict[int, list[tuple[float, bytes]]] = {}
            self._decoded: dict[int, list[dict[str, Any]]] = {}
            self._monitor = E2EMonitor(self.db)

    def on_message_received(self, msg: can.Message) -> None:
        """Keep one frame (python-can ``Listener``)."""
        with self._lock:
            if self._restamp is not None:
                if self._offset is None:
                    self._offset = msg.timestamp - self._restamp()
                msg.timestamp -= self._offset + self._origin_s
            self._collector.on_message_received(msg)
            if not (msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id):
                self._raw.setdefault(msg.arbitration_id, []).append(
                    (msg.timestamp, bytes(msg.data))
                )

    def arrays(self) -> FrameArrays:
        """Every frame heard, as arrays (``host.logio``)."""
        with self._lock:
            return self._collector.arrays()

    def __len__(self) -> int:
        with self._lock:
            return len(self._collector)

    def decoded(self, name: str) -> list[dict[str, Any]]:
        """The frames of message ``name`` that passed their E2E check, decoded (a copy)."""
        try:
            message = self.db.get_message_by_name(name)
        except KeyError:
            known = ", ".join(sorted(m.name for m in self.db.messages))
            raise TestkitError(f"the DBC has no message {name!r} (known: {known})") from None
        with self._lock:
            done = self._decoded.setdefault(message.frame_id, [])
            raw = self._raw.get(message.frame_id, [])
            for timestamp, data in raw[len(done) :]:
                done.append(self._decode(message, timestamp, data))
            return [d for d in done if d]

    def _decode(self, message: Any, timestamp: float, data: bytes) -> dict[str, Any]:
        """One frame's signals (choices by name) and ``timestamp_s``; {} when it is rejected."""
        status = self._monitor.check(message.frame_id, data, timestamp_s=timestamp)
        if status not in _ACCEPTED:
            return {}
        try:
            signals = message.decode(data, decode_choices=True)
        except (cantools.database.DecodeError, ValueError):
            return {}
        plain = {k: str(v) if isinstance(v, NamedSignalValue) else v for k, v in signals.items()}
        plain["timestamp_s"] = timestamp
        return plain


# --- the backends -----------------------------------------------------------------------------


class Backend(Protocol):
    """What ``OdocanRig`` needs of the world around the firmware."""

    mode: str  # "lockstep" or "external"
    recorder: Recorder
    ack_timeout_s: float

    def now_s(self) -> float:
        """Seconds since the backend started."""
        ...

    def advance(self, seconds: float) -> None:
        """Let ``seconds`` pass (simulated or wall clock)."""
        ...

    def advance_until(self, done: Callable[[], bool], timeout_s: float) -> bool:
        """Let time pass until ``done()`` or ``timeout_s``; True when ``done()`` held."""
        ...

    def send(self, can_id: int, data: bytes) -> None:
        """Send a frame as the HOST."""
        ...

    def set_scenario(self, scenario: Scenario | None) -> None:
        """Drive the motors with ``scenario`` from now on (its t = 0 is now); None: stop it."""
        ...

    def truth(self) -> Pose:
        """The simulated robot's true pose now."""
        ...

    def buses(self) -> tuple[can.BusABC, ...]:
        """Every bus handle the backend opened."""
        ...

    def close(self) -> None:
        """Stop and release every bus handle."""
        ...


class _Shifted:
    """A scenario started at ``start_s`` of the rig's clock instead of at 0."""

    def __init__(self, scenario: Scenario, start_s: float) -> None:
        self.name = scenario.name
        self.default_duration_s = scenario.default_duration_s
        self._scenario = scenario
        self._start_s = start_s

    def command_at(self, t_s: float) -> tuple[float, float]:
        """The scenario's setpoints ``t_s - start_s`` into it."""
        return self._scenario.command_at(t_s - self._start_s)


def _pose_of(truth: Any) -> Pose:
    return Pose(float(truth.x_m), float(truth.y_m), float(truth.heading_rad))


class LockstepBackend:
    """Our firmware in a ``LockstepRig``, closed loop, on a virtual channel of its own."""

    mode = "lockstep"
    ack_timeout_s = _LOCKSTEP_ACK_TIMEOUT_S

    def __init__(self, options: RigOptions) -> None:
        self.recorder = Recorder(contract.database())
        config = RigConfig(
            robot=options.profile(),
            integrator=options.integrator,
            scenario=None,
            seed=options.seed,
            errors=options.error_model(),
            channel=f"odocan-testkit-{next(_channels)}",
            faults=_fault_spec(options.faults),
            fw_faults=_fault_spec(options.fw_faults),
        )
        self.rig = LockstepRig(config, [self.recorder])

    def now_s(self) -> float:
        """Simulated seconds of the next tick."""
        return self.rig.ticks * TICK_S

    def advance(self, seconds: float) -> None:
        """Run ``seconds`` of simulated time."""
        self.rig.run(seconds)

    def advance_until(self, done: Callable[[], bool], timeout_s: float) -> bool:
        """Step until ``done()`` (checked after each tick) or ``timeout_s`` simulated seconds."""
        return done() or self.rig.run_until(done, timeout_s)

    def send(self, can_id: int, data: bytes) -> None:
        """Send as the HOST; the firmware takes it in the next tick."""
        self.rig.send(can_id, data)

    def set_scenario(self, scenario: Scenario | None) -> None:
        """A scenario driver on the sim's handle from the next tick on (None: none)."""
        self.rig.sim.set_scenario(None if scenario is None else _Shifted(scenario, self.now_s()))

    def truth(self) -> Pose:
        """The vehicle's true pose (float64)."""
        return _pose_of(self.rig.vehicle.truth())

    def buses(self) -> tuple[can.BusABC, ...]:
        """The sim's, the firmware's and the host's handles."""
        rig = self.rig
        return (rig.motor_controller.bus, rig.board.bus, rig.host_bus)

    def close(self) -> None:
        """Close the rig (listeners and buses)."""
        self.rig.close()


def parse_bus_spec(text: str) -> dict[str, Any]:
    """``"interface=udp_multicast,channel=239.74.163.9,hop_limit=0"`` -> ``can.Bus`` keywords
    (numbers and true/false converted)."""
    kwargs: dict[str, Any] = {}
    for item in (part.strip() for part in text.split(",")):
        if not item:
            continue
        key, sep, value = (s.strip() for s in item.partition("="))
        if not sep or not key:
            raise BusSetupError(f"odocan bus: expected KEY=VALUE, got {item!r}")
        kwargs[key] = _auto_type(value)
    if not kwargs:
        raise BusSetupError("odocan bus: empty specification (e.g. interface=udp_multicast,...)")
    return kwargs


def _auto_type(text: str) -> Any:
    if text.lower() in ("true", "false"):
        return text.lower() == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def open_bus(kwargs: dict[str, Any]) -> can.BusABC:
    """``can.Bus(**kwargs)`` (a udp_multicast group on its own port, as every odocan node:
    ``host.io.buses.isolated_bus_kwargs``); a one-line ``BusSetupError`` when it cannot be
    opened."""
    kwargs = isolated_bus_kwargs(kwargs)
    try:
        return can.Bus(**kwargs)
    except (can.CanError, ValueError, OSError, ImportError, TypeError) as exc:
        described = ", ".join(f"{k}={v}" for k, v in kwargs.items())
        raise BusSetupError(f"cannot open CAN bus ({described}): {exc}") from exc


class ExternalBackend:
    """The robot around an external firmware, in real time on a real bus (module docstring)."""

    mode = "external"
    ack_timeout_s = _EXTERNAL_ACK_TIMEOUT_S

    def __init__(self, options: RigOptions, bus_kwargs: dict[str, Any]) -> None:
        self.clock = RealTimeClock()
        self.recorder = Recorder(contract.database(), restamp=self.clock.now_s)
        self._buses: list[can.BusABC] = [open_bus(bus_kwargs)]
        self._buses.append(open_bus(bus_kwargs))
        host_bus, sim_bus = self._buses
        spec = _fault_spec(options.faults)
        if spec is not None:
            sim_bus = FaultInjectingBus(sim_bus, spec, clock=self.clock.now_s)
        self._host_bus = host_bus
        vehicle = Vehicle(options.profile(), options.error_model(), seed=options.seed)
        self.sim = SimNode(sim_bus, vehicle, self.clock, None)
        self._outbox: queue.SimpleQueue[tuple[int, bytes]] = queue.SimpleQueue()
        self._lock = threading.Lock()  # the vehicle and the driver
        self._loop = PeriodicLoop(TICK_S, self.clock)
        self._failure: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="odocan-sim", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            self._loop.run(self._tick)
        except BaseException as exc:  # reported to the test thread at its next wait
            self._failure = exc

    def _tick(self, k: int) -> None:
        """Host frames out; then MOTOR_CTRL, driver, encoders, truth; then what the host heard."""
        while True:
            try:
                can_id, data = self._outbox.get_nowait()
            except queue.Empty:
                break
            self._host_bus.send(can.Message(arbitration_id=can_id, is_extended_id=False, data=data))
        with self._lock:
            self.sim.tick(k)
        msg = self._host_bus.recv(0)
        while msg is not None:
            self.recorder.on_message_received(msg)
            msg = self._host_bus.recv(0)

    def now_s(self) -> float:
        """Wall-clock seconds since the backend started."""
        return self.clock.now_s()

    def _check_alive(self) -> None:
        if self._failure is not None:
            raise TestkitError(f"the real-time sim thread failed: {self._failure!r}")

    def advance(self, seconds: float) -> None:
        """Sleep ``seconds`` while the robot lives on."""
        self.advance_until(lambda: False, seconds)

    def advance_until(self, done: Callable[[], bool], timeout_s: float) -> bool:
        """Poll ``done()`` every 10 ms of the wall clock for up to ``timeout_s``."""
        end = time.monotonic() + timeout_s
        while True:
            self._check_alive()
            if done():
                return True
            left = end - time.monotonic()
            if left <= 0:
                return False
            time.sleep(min(_POLL_S, left))

    def send(self, can_id: int, data: bytes) -> None:
        """Queue a HOST frame; the sim thread sends it at its next tick."""
        self._outbox.put((can_id, data))

    def set_scenario(self, scenario: Scenario | None) -> None:
        """A scenario driver on the sim's handle from now on (None: none)."""
        with self._lock:
            self.sim.set_scenario(
                None if scenario is None else _Shifted(scenario, self.clock.now_s())
            )

    def truth(self) -> Pose:
        """The vehicle's true pose now."""
        with self._lock:
            return _pose_of(self.sim.vehicle.truth())

    def buses(self) -> tuple[can.BusABC, ...]:
        """The host's and the sim's handles."""
        return tuple(self._buses)

    def close(self) -> None:
        """Stop the sim thread, then close both handles."""
        self._loop.request_stop()
        self._thread.join(timeout=5.0)
        for bus in self._buses:
            bus.shutdown()


# --- the driver -------------------------------------------------------------------------------


def _fmt(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.3g}"


class OdocanRig:
    """Drive a firmware under test and judge its odometry from the bus (module docstring)."""

    def __init__(
        self, backend: Backend, options: RigOptions, encoder: CommandEncoder | None = None
    ) -> None:
        self.backend = backend
        self.options = options
        self.robot = options.profile()
        self._encoder = encoder if encoder is not None else CommandEncoder()
        self._next_goal_id = 1
        self._last_goal_id: int | None = None
        self._goal_acked_at: dict[int, float] = {}
        self._t0 = 0.0
        self._analysis: tuple[int, Analysis] | None = None
        self.closed = False

    # --- set-up and teardown ----------------------------------------------------------------

    @property
    def mode(self) -> str:
        """``"lockstep"`` (our firmware, simulated time) or ``"external"`` (a real bus)."""
        return self.backend.mode

    @property
    def integrator(self) -> str:
        """The integrator the firmware runs (and the reference uses)."""
        return self.options.integrator

    def attach(self, timeout_s: float) -> None:
        """External firmware: wait for it, configure it, put it at the origin, start recording."""
        heard = self.backend.advance_until(lambda: self.odom_status is not None, timeout_s)
        if not heard:
            raise TestkitError(
                f"no ODOM_STATUS from the firmware within {timeout_s:g} s: is it running on "
                "this bus?"
            )
        p = self.robot
        self.command(
            "config",
            {
                "counts_per_rev": p.counts_per_rev,
                "wheel_radius_left_m": p.wheel_radius_left_m,
                "wheel_radius_right_m": p.wheel_radius_right_m,
                "wheelbase_m": p.wheelbase_m,
                "counter_bits": p.counter_bits,
                "integrator": self.integrator,
            },
        )
        if not self.backend.advance_until(self._tracks_our_encoders, timeout_s):
            raise TestkitError(
                f"the firmware's poses do not follow our WHEEL_ENCODERS within "
                f"{timeout_s:g} s (latest ODOM_STATUS: {self.odom_status})"
            )
        acked = self.set_pose(0.0, 0.0, 0.0)
        settled = self.backend.advance_until(lambda: self._at_origin_since(acked), timeout_s)
        if not settled:
            raise TestkitError(
                f"the firmware is not OK at the origin {timeout_s:g} s after "
                f"ODOM_SET_POSE (latest ODOM_STATUS: {self.odom_status})"
            )
        self._t0 = self.backend.now_s()
        self.backend.recorder.reset(self._t0)

    def _tracks_our_encoders(self) -> bool:
        """STATE OK, and the last ``_TRACKING_POSES`` ODOM_POSE_X frames each name one of the
        encoder frames sent just before them: the firmware integrates our counters (after a
        restart of the sim its E2E receiver takes up to 16 frames to accept them again, and the
        first one it takes carries the jump from the previous counters)."""
        status = self.odom_status
        poses = self.frames("ODOM_POSE_X")[-_TRACKING_POSES:]
        if not (status and status["STATE"] == "OK" and len(poses) == _TRACKING_POSES):
            return False
        encoders = self.frames("WHEEL_ENCODERS")
        for pose in poses:
            t = pose["timestamp_s"]
            recent = {
                e["COUNTER"] for e in encoders if t - _TRACKING_WINDOW_S <= e["timestamp_s"] <= t
            }
            if pose["ENC_COUNTER"] not in recent:
                return False
        return True

    def _at_origin_since(self, t_s: float) -> bool:
        """STATE OK and a pose sent after ``t_s`` at the origin, exactly."""
        status = self.odom_status
        after = any(f["timestamp_s"] > t_s for f in self.frames("ODOM_POSE_Y"))
        ok = bool(status and status["STATE"] == "OK")
        return ok and after and self.pose == Pose(0.0, 0.0, 0.0)

    def close(self) -> None:
        """Release every bus (idempotent)."""
        if not self.closed:
            self.closed = True
            self.backend.close()

    @property
    def buses(self) -> tuple[can.BusABC, ...]:
        """Every bus handle the rig opened (closed by ``close``)."""
        return self.backend.buses()

    # --- time ---------------------------------------------------------------------------------

    @property
    def now_s(self) -> float:
        """Seconds since the recording started."""
        return self.backend.now_s() - self._t0

    def step(self, seconds: float = TICK_S) -> None:
        """Let ``seconds`` pass (computed in lockstep, slept on a real bus)."""
        self.backend.advance(seconds)

    def run_until(self, done: Callable[[], bool], timeout_s: float) -> bool:
        """Let time pass until ``done()`` holds (True) or ``timeout_s`` passed (False)."""
        return self.backend.advance_until(done, timeout_s)

    # --- driving ------------------------------------------------------------------------------

    def drive(self, scenario: str | Scenario, seconds: float | None = None) -> None:
        """Drive the motors open loop with ``scenario`` (a ``sim.scenarios`` name or object) for
        ``seconds`` (default: its own duration, rest included), then stop driving them."""
        if isinstance(scenario, str):
            scenario = get_scenario(scenario, self.robot, self.options.seed)
        self.backend.set_scenario(scenario)
        try:
            self.step(scenario.default_duration_s if seconds is None else seconds)
        finally:
            self.backend.set_scenario(None)

    def goto(
        self,
        x_m: float,
        y_m: float,
        heading_rad: float | None = None,
        *,
        mode: str = "turn_go_turn",
        append: bool = False,
        goal_id: int | None = None,
    ) -> int:
        """Send a NAV_GOAL (REPLACE the path, or ``append`` to it) once the firmware is OK;
        returns its goal id after the firmware ACKed it (``CommandRefused`` on NACK)."""
        if goal_id is None:
            goal_id = self._next_goal_id
        self._next_goal_id = goal_id % 255 + 1
        self._last_goal_id = goal_id
        self.wait_ready()
        payload: dict[str, Any] = {
            "x_m": x_m,
            "y_m": y_m,
            "mode": mode,
            "append": append,
            "goal_id": goal_id,
        }
        if heading_rad is not None:
            payload["heading_rad"] = heading_rad
        self._goal_acked_at[goal_id] = self.command("nav_goal", payload)
        return goal_id

    def path(
        self, waypoints: Iterable[Sequence[float]], *, mode: str = "turn_go_turn"
    ) -> list[int]:
        """Goals through ``(x_m, y_m)`` or ``(x_m, y_m, heading_rad)`` waypoints: the first
        replaces the path, the others are appended; returns their goal ids."""
        ids = []
        for i, point in enumerate(waypoints):
            heading = point[2] if len(point) > 2 else None
            ids.append(self.goto(point[0], point[1], heading, mode=mode, append=i > 0))
        return ids

    def run_until_reached(self, goal_id: int | None = None, timeout_s: float = 60.0) -> None:
        """Let time pass until NAV_STATUS reports ``goal_id`` (default: the last goal sent)
        REACHED; an ``AssertionError`` when it is STOPPED, ABORTED or the time runs out."""
        __tracebackhide__ = True
        if goal_id is None:
            if self._last_goal_id is None:
                raise TestkitError("run_until_reached: no goal was sent (goto or path first)")
            goal_id = self._last_goal_id
        self.backend.advance_until(lambda: self._goal_ended(goal_id), timeout_s)
        self.assert_reached(goal_id)

    def _goal_states(self, goal_id: int) -> list[dict[str, Any]]:
        """NAV_STATUS frames of ``goal_id`` heard since its ACK."""
        since = self._goal_acked_at.get(goal_id, -math.inf)
        return [f for f in self.frames("NAV_STATUS", GOAL_ID=goal_id) if f["timestamp_s"] >= since]

    def _goal_ended(self, goal_id: int) -> bool:
        states = {f["STATE"] for f in self._goal_states(goal_id)}
        return bool(states & {"REACHED", "STOPPED", "ABORTED"})

    def wait_ready(self, timeout_s: float | None = None) -> None:
        """Let time pass until the latest ODOM_STATUS reports STATE OK (``TestkitError`` if not)."""
        timeout = self.backend.ack_timeout_s if timeout_s is None else timeout_s

        def ready() -> bool:
            status = self.odom_status
            return status is not None and status["STATE"] == "OK"

        if not self.backend.advance_until(ready, timeout):
            raise TestkitError(f"the firmware is not OK (latest ODOM_STATUS: {self.odom_status})")

    def set_pose(self, x_m: float, y_m: float, heading_rad: float) -> float:
        """Overwrite the on-board pose (ODOM_SET_POSE); returns the time of the ACK.

        The analysis does not follow the jump: use it before driving, not in the middle."""
        return self.command("set_pose", {"x_m": x_m, "y_m": y_m, "heading_rad": heading_rad})

    def command(self, name: str, values: dict[str, Any]) -> float:
        """Send a validated command (``host.commands``: nav_goal, set_pose, config) and
        wait for the ACK of its last frame; returns the ACK's time (``CommandRefused`` on NACK)."""
        __tracebackhide__ = True
        cmd = self._encoder.encode(name, json.dumps(values).encode())
        seen = len(self.frames("ODOM_ACK"))
        for frame in cmd.frames:
            self.backend.send(frame.can_id, frame.data)
        self.backend.advance_until(
            lambda: self._answer(cmd, seen) is not None, self.backend.ack_timeout_s
        )
        answers = self.frames("ODOM_ACK")[seen:]
        nacks = [a for a in answers if a["RESULT"] == "NACK"]
        final = self._answer(cmd, seen)
        if nacks or final is None:
            why = f"NACK {nacks[0]['REASON']}" if nacks else "no ODOM_ACK"
            raise CommandRefused(f"{name} {values}: {why} from the firmware")
        return float(final["timestamp_s"])

    def _answer(self, cmd: Command, seen: int) -> dict[str, Any] | None:
        """The ODOM_ACK of ``cmd``'s last frame among the ACKs after the first ``seen``."""
        last = cmd.frames[-1]
        name = self.backend.recorder.db.get_message_by_frame_id(last.can_id).name
        for ack in self.frames("ODOM_ACK")[seen:]:
            if ack["REQUEST_COUNTER"] == last.counter and str(ack["REQUEST_ID"]) == name:
                return ack
        return None

    def send(self, can_id: int, data: bytes) -> None:
        """Send any frame as the HOST (no validation, no E2E: the bytes as given)."""
        self.backend.send(can_id, data)

    # --- reading ------------------------------------------------------------------------------

    def frames(self, name: str, **match: Any) -> list[dict[str, Any]]:
        """Every frame of message ``name`` heard so far that passed its E2E check, decoded by
        cantools (scaled values, choices by name) with ``timestamp_s``; ``match`` keeps the frames
        whose signals have those values, e.g. ``frames("ODOM_STATUS", PAGE="SUMMARY")``."""
        decoded = self.backend.recorder.decoded(name)
        if not match:
            return decoded
        return [f for f in decoded if all(f.get(k) == v for k, v in match.items())]

    def latest(self, name: str, **match: Any) -> dict[str, Any] | None:
        """The last of ``frames(name, **match)``, None before the first."""
        found = self.frames(name, **match)
        return found[-1] if found else None

    @property
    def nav_status(self) -> dict[str, Any] | None:
        """The latest NAV_STATUS (STATE, GOAL_ID, QUEUE_DEPTH, DISTANCE, HEADING_ERROR)."""
        return self.latest("NAV_STATUS")

    @property
    def odom_status(self) -> dict[str, Any] | None:
        """The latest ODOM_STATUS summary page (STATE, INTEGRATOR, ERROR_MASK, UPTIME)."""
        return self.latest("ODOM_STATUS", PAGE="SUMMARY")

    @property
    def pose(self) -> Pose:
        """The latest on-board pose: ODOM_POSE_X and ODOM_POSE_Y of one encoder frame
        (heading ``TURNS * 2 pi + HEADING``, to 0.1 mm and 2 pi / 65536 rad)."""
        ys = self.frames("ODOM_POSE_Y")
        xs = self.frames("ODOM_POSE_X")
        for y in reversed(ys):
            for x in reversed(xs):
                if x["ENC_COUNTER"] == y["ENC_COUNTER"] and x["timestamp_s"] <= y["timestamp_s"]:
                    return Pose(x["X"], y["Y"], y["TURNS"] * 2 * math.pi + x["HEADING"])
        raise TestkitError("no ODOM_POSE_X/ODOM_POSE_Y pair heard yet: step the rig first")

    @property
    def truth(self) -> Pose:
        """The simulated robot's true pose now (float64; heading wrapped to (-pi, pi])."""
        return self.backend.truth()

    @property
    def reference(self) -> Pose:
        """The float64 reference (``host.reference``, same counts, same integrator) at the last
        on-board sample of the analysis."""
        analysis = self.analysis()
        series = analysis.series
        final = analysis.report["final_onboard_pose"]
        heading = final["heading_rad"] - float(series["heading_error_rad"][-1])
        return Pose(float(series["reference_x_m"][-1]), float(series["reference_y_m"][-1]), heading)

    def analysis(self) -> Analysis:
        """``host.analysis.analyze`` over every frame heard (recomputed when frames came in)."""
        heard = len(self.backend.recorder)
        if self._analysis is None or self._analysis[0] != heard:
            frames = self.backend.recorder.arrays()
            self._analysis = (
                heard,
                analyze(frames, self.robot, self.integrator, seed=self.options.seed),
            )
        return self._analysis[1]

    def report(self) -> dict[str, Any]:
        """The analysis report (``onboard_vs_reference``, ``onboard_vs_truth``, ``e2e``, ...)."""
        return self.analysis().report

    # --- judging ------------------------------------------------------------------------------

    def assert_pose_matches_reference(
        self, position_m: float = POSITION_LSB_M, heading_rad: float = HEADING_LSB_RAD
    ) -> None:
        """Every on-board sample within ``position_m`` (distance) and ``heading_rad`` of the
        float64 reference (defaults: one LSB of the pose signals, 0.1 mm and 2 pi / 65536)."""
        __tracebackhide__ = True
        report = self.report()
        errors = report["onboard_vs_reference"]
        where = (
            f"on-board pose vs float64 reference ({self.integrator}, "
            f"{report['samples']['onboard']} samples over {report['sim_seconds']:.2f} s)"
        )
        _check_limits(where, errors, position_m, heading_rad)

    def assert_near_truth(self, position_m: float, heading_rad: float | None = None) -> None:
        """Every on-board sample with a SIM_TRUTH sample of its encoder frame within
        ``position_m`` (distance) and ``heading_rad`` (None: not checked) of the ground truth."""
        __tracebackhide__ = True
        report = self.report()
        errors = report["onboard_vs_truth"]
        compared = report["samples"]["truth_compared"]
        where = (
            f"on-board pose vs ground truth ({compared} samples over "
            f"{errors['distance_travelled_m']:.3f} m, errors {self.options.errors or 'none'})"
        )
        if compared == 0:
            raise AssertionError(f"{where}: no SIM_TRUTH sample to compare with")
        _check_limits(where, errors, position_m, heading_rad)

    def assert_reached(self, goal_id: int) -> None:
        """NAV_STATUS reported ``goal_id`` REACHED (since the firmware ACKed it)."""
        __tracebackhide__ = True
        states = self._goal_states(goal_id)
        if any(f["STATE"] == "REACHED" for f in states):
            return
        if not states:
            latest = self.nav_status
            seen = "none" if latest is None else f"goal {latest['GOAL_ID']} {latest['STATE']}"
            raise AssertionError(
                f"goal {goal_id} not reached at t = {self.now_s:.2f} s: no NAV_STATUS for it "
                f"(latest NAV_STATUS: {seen})"
            )
        last = states[-1]
        path = " -> ".join(s for s, _ in itertools.groupby(f["STATE"] for f in states))
        raise AssertionError(
            f"goal {goal_id} not reached at t = {self.now_s:.2f} s: {last['STATE']}, "
            f"{last['DISTANCE']:.3f} m and {last['HEADING_ERROR']:.4f} rad to go, "
            f"pose {self._pose_text()} (states: {path})"
        )

    def _pose_text(self) -> str:
        try:
            x, y, heading = self.pose
        except TestkitError:
            return "unknown"
        return f"({x:.4f} m, {y:.4f} m, {heading:.4f} rad)"


def _check_limits(
    where: str, errors: dict[str, Any], position_m: float, heading_rad: float | None
) -> None:
    """An AssertionError naming every limit exceeded, with the numbers."""
    __tracebackhide__ = True
    failures = []
    position = errors["max_position_error_m"]
    if position is None:
        raise AssertionError(f"{where}: no sample to compare")
    if position > position_m:
        failures.append(
            f"max position error {_fmt(position)} m > {_fmt(position_m)} m "
            f"(final {_fmt(errors['final_position_error_m'])} m)"
        )
    heading = errors["max_heading_error_rad"]
    if heading_rad is not None and heading > heading_rad:
        failures.append(
            f"max heading error {_fmt(heading)} rad > {_fmt(heading_rad)} rad "
            f"(final {_fmt(errors['final_heading_error_rad'])} rad)"
        )
    if failures:
        raise AssertionError(f"{where}: " + "; ".join(failures))


def make_rig(
    options: RigOptions,
    *,
    bus: dict[str, Any] | None = None,
    encoder: CommandEncoder | None = None,
    attach_timeout_s: float = 30.0,
) -> OdocanRig:
    """A rig: lockstep with our firmware (``bus`` None), or around the external firmware on
    ``bus`` (``can.Bus`` keywords), attached within ``attach_timeout_s``."""
    if bus is None:
        return OdocanRig(LockstepBackend(options), options, encoder)
    if _fault_spec(options.fw_faults) is not None:
        raise TestkitError("fw_faults need our firmware (lockstep): the external one sends alone")
    rig = OdocanRig(ExternalBackend(options, bus), options, encoder)
    try:
        rig.attach(attach_timeout_s)
    except BaseException:
        rig.close()
        raise
    return rig
