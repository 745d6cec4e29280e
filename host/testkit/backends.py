"""Where the firmware under test runs: in lockstep with ours, or on a real bus around any firmware.

* ``LockstepBackend``: our firmware in a ``sim.rig.LockstepRig`` (closed loop, simulated time):
  ``advance`` computes, deterministic for a seed.
* ``ExternalBackend``: ANY firmware that speaks the DBC, already running on a real bus; the backend
  plays the rest of the robot in real time in a thread and a host handle hears every frame.
"""

from __future__ import annotations

import itertools
import queue
import threading
import time
from collections.abc import Callable
from typing import Any, Protocol

import can

from odocan.host.io.buses import auto_type, isolated_bus_kwargs
from odocan.host.protocol.heard import Recorder
from odocan.host.protocol.pose import Pose
from odocan.host.protocol.secoc import load_secoc_key
from odocan.host.testkit.options import RigOptions, TestkitError, fault_spec
from odocan.sim import contract
from odocan.sim.board import TICK_S
from odocan.sim.clock import RealTimeClock
from odocan.sim.exceptions import BusSetupError
from odocan.sim.faults import FaultInjectingBus
from odocan.sim.faultspec import mcu_refused
from odocan.sim.motor_controller import SimNode
from odocan.sim.realtime import PeriodicLoop, ReleaseClock, paced_sim_tick
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.scenarios import Scenario
from odocan.sim.tickloop import TickLoop
from odocan.sim.vehicle import Vehicle

_LOCKSTEP_ACK_TIMEOUT_S = 1.0  # simulated seconds for an ODOM_ACK (it comes in the next tick)
EXTERNAL_ACK_TIMEOUT_S = 3.0  # wall-clock seconds on a real bus (ini odocan_ack_timeout)
_POLL_S = 0.01  # how often a real-time wait looks at what was heard
_channels = itertools.count()

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
            # the seeds follow the rig's as ``odocan run``'s do (the firmware's seed + 1)
            faults=fault_spec(options.faults, options.seed),
            fw_faults=fault_spec(options.fw_faults, options.seed + 1),
            firmware=options.firmware,
            secoc_key=load_secoc_key(options.secoc_key) if options.secoc_key else None,
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
        return self.rig.vehicle.truth().pose

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
        kwargs[key] = auto_type(value)
    if not kwargs:
        raise BusSetupError("odocan bus: empty specification (e.g. interface=udp_multicast,...)")
    return kwargs


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

    def __init__(self, options: RigOptions, bus_kwargs: dict[str, Any],
                 ack_timeout_s: float = EXTERNAL_ACK_TIMEOUT_S) -> None:
        self.ack_timeout_s = ack_timeout_s  # wall clock: a loaded CI machine may need more
        spec = fault_spec(options.faults, options.seed)
        if spec is not None and spec.mcu_active:  # no rig steps an external MCU: before a bus
            raise mcu_refused(spec)
        self.clock = RealTimeClock()
        self.recorder = Recorder(contract.database(), restamp=self.clock.now_s)
        self._buses: list[can.BusABC] = [open_bus(bus_kwargs)]
        self._buses.append(open_bus(bus_kwargs))
        host_bus, sim_bus = self._buses
        if spec is not None:
            sim_bus = FaultInjectingBus(sim_bus, spec, clock=self.clock.now_s)
        self._host_bus = host_bus
        vehicle = Vehicle(options.profile(), options.error_model(), seed=options.seed)
        # The sim samples at its tick's release, not when the thread got the CPU, and sends a
        # skipped release's sample late (``sim.realtime.paced_sim_tick``, as ``odocan sim``).
        self._release = ReleaseClock()
        self.sim = SimNode(sim_bus, vehicle, self._release, None)
        self._outbox: queue.SimpleQueue[tuple[int, bytes]] = queue.SimpleQueue()
        self._lock = threading.Lock()  # the vehicle and the driver
        paced = paced_sim_tick(self, self._release, TICK_S)
        self._tick_loop = TickLoop(paced, host_bus, [self.recorder])  # real time: no clock
        self._loop = PeriodicLoop(TICK_S, self.clock)
        self._failure: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="odocan-sim", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            self._loop.run(self._tick_loop.tick)
        except BaseException as exc:  # reported to the test thread at its next wait
            self._failure = exc

    def sample_skipped(self) -> None:
        """A skipped release's encoder sample, at the release clock's time, sent now (run by
        ``paced_sim_tick`` before the tick the loop got to)."""
        with self._lock:
            self.sim.sample_skipped()

    def tick(self, k: int) -> None:
        """Tick ``k`` (``paced_sim_tick`` set the release clock to it): host frames out; then
        MOTOR_CTRL, driver, encoders, truth (``sim.tickloop`` then hands what the host heard
        to the recorder)."""
        while True:
            try:
                can_id, data = self._outbox.get_nowait()
            except queue.Empty:
                break
            self._host_bus.send(can.Message(arbitration_id=can_id, is_extended_id=False, data=data))
        with self._lock:
            self.sim.tick(k)

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
            self.sim.set_scenario(  # on the sim's clock: its latest release
                None if scenario is None else _Shifted(scenario, self._release.now_s())
            )

    def truth(self) -> Pose:
        """The vehicle's true pose now."""
        with self._lock:
            return self.sim.vehicle.truth().pose

    def buses(self) -> tuple[can.BusABC, ...]:
        """The host's and the sim's handles."""
        return tuple(self._buses)

    def close(self) -> None:
        """Stop the sim thread, then close both handles."""
        self._loop.request_stop()
        self._thread.join(timeout=5.0)
        for bus in self._buses:
            bus.shutdown()


