"""The simulated nodes around the firmware: motor controller, ground truth, scenario driver.

* ``MotorController`` (node MOTOR_CTRL): follows E2E-checked ``MOTOR_CMD`` frames and sends
  ``WHEEL_ENCODERS`` every cycle (the low 24 bits of each wrapping hardware counter).
* ``TruthSender`` (node SIM): ``SIM_TRUTH`` (X, Y, HEADING parts) of the vehicle's ground truth at
  the instant of an encoder frame, echoing its COUNTER.
* ``ScenarioDriver`` (a HOST role): sends an open-loop scenario's wheel speeds as ``MOTOR_CMD``.

They share one bus handle in the sim process. A CAN controller hears its own frames only when asked
to, so the driver's commands reach the motor controller by ``deliver`` as well as on the bus.
"""

from __future__ import annotations

import math

import can

from odocan.firmware import frames as fr
from odocan.firmware.e2e import MAX_DELTA_COUNTER_LIMIT, E2EReceiver, E2EStatus
from odocan.firmware.errors import ErrorMask
from odocan.sim.board import TICK_S
from odocan.sim.clock import Clock
from odocan.sim.contract import cycle_ticks
from odocan.sim.e2efacts import MOTOR_CMD, SIM_TRUTH, WHEEL_ENCODERS, message_e2e
from odocan.sim.errors import ErrorModel
from odocan.sim.frames import (
    SimTruthPart,
    ctrl_uptime_code,
    enc_counter_mask,
    pack_sim_truth,
    pack_wheel_encoders,
    unpack_motor_cmd,
)
from odocan.sim.lookahead import PlannedVehicle
from odocan.sim.node import BusNode
from odocan.sim.robot import RobotProfile
from odocan.sim.scenarios import Scenario, get_scenario
from odocan.sim.simplan import TickPlan, plan_ticks
from odocan.sim.transport import OdocanBus
from odocan.sim.vehicle import Vehicle

_U24 = 0xFF_FFFF
_BAM16_PER_RAD = 65536 / (2 * math.pi)


class MotorController(BusNode):
    """Node MOTOR_CTRL: two wheel motors and their encoders, driven over CAN."""

    def __init__(self, bus: can.BusABC, vehicle: Vehicle, clock: Clock) -> None:
        super().__init__(bus, clock)
        self.vehicle = vehicle
        # the COUNTER lap and data IDs of what it sends and takes: the DBC's (sim.e2efacts)
        self.e2e, self.cmd_e2e = message_e2e(WHEEL_ENCODERS), message_e2e(MOTOR_CMD)
        self.rx_motor_cmd = E2EReceiver(self.cmd_e2e.data_ids,
                                        max_delta_counter_init=MAX_DELTA_COUNTER_LIMIT)
        self.errors = ErrorMask()
        self.counter = -1
        self.commands_applied = 0
        self._count_offset = (0, 0)  # the vehicle's counts at the last restart
        self.powered_up_s = clock.now_s()  # the clock's time at the last power-up (CTRL_UPTIME)

    def deliver(self, data: bytes, speeds_mps: tuple[float, float] | None = None) -> None:
        """One received ``MOTOR_CMD`` payload: applied when its E2E check passes (``speeds_mps``:
        its speeds already decoded, m/s, as here: ``sim.simplan``'s)."""
        status = self.rx_motor_cmd.check(data)
        if status is E2EStatus.OK or status is E2EStatus.OKSOMELOST:
            if speeds_mps is None:
                cmd = unpack_motor_cmd(data)
                speeds_mps = (cmd.left_speed_mm_s / 1000.0, cmd.right_speed_mm_s / 1000.0)
            self.vehicle.command(speeds_mps[0], speeds_mps[1], self.clock.now_s())
            self.commands_applied += 1

    def service_rx(self) -> None:
        """Apply every MOTOR_CMD waiting on the bus (other frames are not for this node)."""
        msg = self.bus.recv(0)
        while msg is not None:
            if msg.arbitration_id == fr.MOTOR_CMD_ID and not msg.is_extended_id:
                self.deliver(bytes(msg.data))
            msg = self.bus.recv(0)

    def restart(self) -> None:
        """A reboot of this node: the encoder counters and the E2E counter start again from 0,
        its age (CTRL_UPTIME) from 1 (the robot stays where it is)."""
        self.vehicle.advance_to(self.clock.now_s())
        self.powered_up_s = self.clock.now_s()
        self._count_offset = self.vehicle.encoder_counts()
        self.counter = -1
        self.rx_motor_cmd.reset()

    def sample_and_send(self) -> int:
        """Advance the motors to now, send WHEEL_ENCODERS (with CTRL_UPTIME, this node's age
        by its clock: deterministic in lockstep); returns the frame's COUNTER."""
        now_s = self.clock.now_s()
        self.vehicle.advance_to(now_s)
        mask = (1 << self.vehicle.profile.counter_bits) - 1
        left, right = self.vehicle.encoder_counts()
        left = (left - self._count_offset[0]) & mask
        right = (right - self._count_offset[1]) & mask
        self.counter = (self.counter + 1) & self.e2e.counter_mask
        uptime = ctrl_uptime_code(now_s - self.powered_up_s)
        self.send_frame(
            fr.WHEEL_ENCODERS_ID,
            pack_wheel_encoders(self.counter, left & _U24, right & _U24, uptime,
                                data_ids=self.e2e.data_ids),
        )
        return self.counter


class TruthSender(BusNode):
    """Node SIM: the ground truth as SIM_TRUTH (0.1 mm, BAM16), aligned to an encoder frame."""

    def __init__(self, bus: can.BusABC, vehicle: Vehicle, clock: Clock) -> None:
        super().__init__(bus, clock)
        self.vehicle = vehicle
        self.errors = ErrorMask()
        self.counter = -1
        self.e2e = message_e2e(SIM_TRUTH)  # its COUNTER lap and data IDs: the DBC's
        self.enc_counter_mask = enc_counter_mask()  # ENC_COUNTER's width: the DBC's

    def send(self, enc_counter: int) -> None:
        """Send the three SIM_TRUTH parts of the truth now."""
        pose = self.vehicle.truth()
        parts = (
            (SimTruthPart.X, round(pose.x_m * 1e4)),
            (SimTruthPart.Y, round(pose.y_m * 1e4)),
            (SimTruthPart.HEADING, round(pose.heading_rad * _BAM16_PER_RAD) & 0xFFFF),
        )
        for part, value in parts:
            self.counter = (self.counter + 1) & self.e2e.counter_mask
            data = pack_sim_truth(self.counter, part, enc_counter, value, self.errors,
                                  (self.enc_counter_mask, self.e2e.data_ids))
            self.send_frame(fr.SIM_TRUTH_ID, data)


class ScenarioDriver(BusNode):
    """A HOST role: an open-loop scenario's wheel speeds as MOTOR_CMD frames."""

    def __init__(
        self,
        bus: can.BusABC,
        scenario: Scenario,
        clock: Clock,
        motor_controller: MotorController | None = None,
    ) -> None:
        super().__init__(bus, clock)
        self.scenario = scenario
        self.local = motor_controller
        self.errors = ErrorMask()
        self.counter = -1
        self.e2e = message_e2e(MOTOR_CMD)  # its COUNTER lap and data IDs: the DBC's
        # Commands a forecast computed ahead (``command_at``), by time, and for which scenario.
        self._ahead: dict[float, tuple[float, float]] = {}
        self._ahead_of: Scenario | None = None

    def command_at(self, t_s: float) -> tuple[float, float]:
        """The scenario's command at ``t_s``, kept until ``send`` takes it (a scenario is a pure
        function of time: the forecast of ``sim.lookahead`` and the send share one call)."""
        if self._ahead_of is not self.scenario:
            self._ahead, self._ahead_of = {}, self.scenario
        command = self._ahead[t_s] = self.scenario.command_at(t_s)
        return command

    def send(self) -> None:
        """Send the scenario's command for now (and deliver it locally)."""
        now_s = self.clock.now_s()
        ahead = self._ahead.pop(now_s, None) if self._ahead_of is self.scenario else None
        left_mps, right_mps = self.scenario.command_at(now_s) if ahead is None else ahead
        self.counter = (self.counter + 1) & self.e2e.counter_mask
        data = fr.pack_motor_cmd(
            self.counter, round(left_mps * 1000), round(right_mps * 1000), self.errors
        )
        if self.e2e.data_ids != fr.MOTOR_CMD_DATA_IDS:  # the DBC's, not the firmware's build
            data = fr.seal_frame(fr.frame_word(data) & ~0xFF, self.e2e.data_ids)  # CRC anew
        self.send_frame(fr.MOTOR_CMD_ID, data)
        if self.local is not None:
            self.local.deliver(data)


class SimNode:
    """MOTOR_CTRL, SIM and an optional scenario driver on one bus handle: the sim side of every
    rig (lockstep, real time, the pytest plugin's external backend). Each 10 ms tick ``k``: take
    MOTOR_CMD, the driver's command (every 20 ms), sample and send WHEEL_ENCODERS, SIM_TRUTH at
    its cycle (on ticks ``k = truth_phase_ticks`` modulo it)."""

    def __init__(
        self,
        bus: can.BusABC,
        vehicle: Vehicle,
        clock: Clock,
        scenario: Scenario | None,
        *,
        truth_phase_ticks: int = 0,
    ) -> None:
        self.bus = bus
        self.clock = clock
        self.vehicle = vehicle
        self.motor_controller = MotorController(bus, vehicle, clock)
        self.truth = TruthSender(bus, vehicle, clock)
        self.driver: ScenarioDriver | None = None
        self.set_scenario(scenario)
        self.truth_phase_ticks = truth_phase_ticks
        self._driver_ticks = cycle_ticks("MOTOR_CMD", TICK_S)
        self._truth_ticks = cycle_ticks("SIM_TRUTH", TICK_S)
        self._plan: TickPlan | None = None  # the current block's frames (sim.simplan)

    @classmethod
    def build(
        cls,
        bus: can.BusABC,
        robot: RobotProfile,
        clock: Clock,
        *,
        scenario: str | None = "random",
        seed: int = 0,
        errors: ErrorModel | None = None,
        quadrature: bool = False,
        duration_s: float | None = None,
        truth_phase_ticks: int = 0,
    ) -> SimNode:
        """A vehicle at rest at the origin, driven by the scenario named (None: no driver)."""
        vehicle = Vehicle(robot, errors, seed=seed, quadrature=quadrature)
        program = None if scenario is None else get_scenario(scenario, robot, seed, duration_s)
        return cls(bus, vehicle, clock, program, truth_phase_ticks=truth_phase_ticks)

    def set_scenario(self, scenario: Scenario | None) -> None:
        """Drive ``scenario`` from now on (None: no driver, e.g. the firmware navigates)."""
        self.driver = (
            None
            if scenario is None
            else ScenarioDriver(self.bus, scenario, self.clock, self.motor_controller)
        )

    def sample_skipped(self) -> None:
        """A skipped real-time release: the motor controller's encoder sample at the clock's
        time, sent now (``sim.realtime.paced_sim_tick``); nothing else of the tick runs."""
        self.motor_controller.sample_and_send()

    def hold_halted(self, ticks: range) -> None:
        """A halt (``sim.fleet``): the releases of ``ticks`` will send their encoder samples
        alone (``sample_skipped``), none of the driver's MOTOR_CMDs, so the robot keeps its
        latest command through them. A drive run ahead is told (``PlannedVehicle.hold``: it
        stays planned instead of falling back at the first command that does not come), and
        the tick plan, made with those commands, is dropped: the tick after the gap plans
        anew."""
        vehicle = self.vehicle
        if isinstance(vehicle, PlannedVehicle):
            vehicle.hold(ticks)
        self._plan = None

    def drive_skipped(self, k: int) -> None:
        """A skipped real-time release of tick ``k`` (the clock at its time) on a robot whose
        drive is the scenario's: the driver's MOTOR_CMD of the tick when it has one (open loop,
        a function of time: a late simulator loop does not stop the host's drive), then the
        encoder sample, both sent now (``sim.fleet.Fleet.step``). The robot moves as it would
        have without the skip, so a drive run ahead (``sim.lookahead``) serves both from its
        block instead of falling back; the truth is not sent (nothing else of the tick runs).
        When the tick's plan (``sim.simplan``) holds and has no truth at it, the plan sends
        both (the same bytes, and it still holds for the next tick); else it is dropped (a
        truth skipped: its COUNTER stays behind the plan's) and the next tick plans anew."""
        plan = self._plan
        if plan is not None:
            i = plan.at(self, k)
            if i >= 0 and not plan.truths[i]:
                self._send_planned(plan, i)
                return
        self._plan = None
        if self.driver is not None and k % self._driver_ticks == 0:
            self.driver.send()
        self.motor_controller.sample_and_send()

    def tick(self, k: int) -> None:
        """Tick ``k`` (10 ms each), in the order of the class docstring: from the plan of the
        vehicle's block when it holds (``sim.simplan``: the same frames, computed at once)."""
        plan = self._plan
        i = -1 if plan is None else plan.at(self, k)
        if i < 0 and self._can_plan(k):
            plan = self._plan = plan_ticks(self, self.vehicle, k)  # type: ignore[arg-type]
            i = -1 if plan is None else plan.at(self, k)
        if i >= 0:
            assert plan is not None
            self._send_planned(plan, i)
            return
        self.motor_controller.service_rx()
        if self.driver is not None and k % self._driver_ticks == 0:
            self.driver.send()
        enc_counter = self.motor_controller.sample_and_send()
        if (k - self.truth_phase_ticks) % self._truth_ticks == 0:
            self.truth.send(enc_counter)

    def _can_plan(self, k: int) -> bool:
        """A plan may be made at tick ``k``: the vehicle runs ahead, the bus is the lean
        transport's instant handle, and no plan of the vehicle's current block failed."""
        vehicle = self.vehicle
        if not isinstance(vehicle, PlannedVehicle) or vehicle.fell_back:
            return False
        bus = self.bus
        if type(bus) is not OdocanBus or bus.timing is not None or not bus._open:
            return False
        plan = self._plan  # one that failed at a tick of its own stays failed (no retry)
        return plan is None or not plan.first <= k < plan.first + len(plan.times)

    def _send_planned(self, plan: TickPlan, i: int) -> None:
        """The plan's tick at index ``i``: its frames and every state change of the plain
        tick. The vehicle's calls go by the tick's substep (``PlannedVehicle.served_command``,
        ``served_advance``: the plan holds, so its block serves them), the MOTOR_CMD is
        ``MotorController.deliver``'s (E2E check, then the command at the clock's time,
        ``t_s``)."""
        bus: OdocanBus = self.bus  # type: ignore[assignment]  # a plan's bus (``_can_plan``)
        vehicle: PlannedVehicle = self.vehicle  # type: ignore[assignment]  # and vehicle
        t_s, n = plan.times[i], plan.substeps[i]
        # ``OdocanBus.send_data``'s own path on the open instant handle: one call less a frame
        send = bus._wire.deliver_data if bus._open and bus.preserve_timestamps else _send_data
        mc, counters = self.motor_controller, plan.after[i]  # the COUNTERs after the tick
        motor_cmd = plan.motor_cmds[i]
        if motor_cmd is not None:
            driver = self.driver
            assert driver is not None
            data, (left_mps, right_mps) = motor_cmd
            driver._ahead.pop(t_s, None)
            driver.counter = counters[0]
            send(bus, t_s + driver.tx_latency_s, fr.MOTOR_CMD_ID, data)
            driver.frames_sent += 1
            status = mc.rx_motor_cmd.check(data)
            if status is E2EStatus.OK or status is E2EStatus.OKSOMELOST:
                vehicle.served_command(n, left_mps, right_mps, t_s)
                mc.commands_applied += 1
        vehicle.served_advance(n, t_s)
        mc.counter = counters[1]
        send(bus, t_s + mc.tx_latency_s, fr.WHEEL_ENCODERS_ID, plan.encoders[i])
        mc.frames_sent += 1
        sim_truth = plan.truths[i]
        if sim_truth:
            truth = self.truth
            for data in sim_truth:
                send(bus, t_s + truth.tx_latency_s, fr.SIM_TRUTH_ID, data)
            truth.counter = counters[2]
            truth.frames_sent += 3
        plan.next = i + 1
        plan.counters = counters

    def planned_command(self, k: int, t_s: float) -> tuple[float, float] | None:
        """The rim speeds (m/s) the motor controller will apply from the driver at tick ``k``
        (at ``t_s``, the clock's time then), as ``MotorController.deliver`` decodes them from
        MOTOR_CMD (whole mm/s), or None when the driver sends nothing then: the forecast of
        ``sim.lookahead.PlannedVehicle`` (checked there against what really comes)."""
        driver = self.driver
        if driver is None or k % self._driver_ticks:
            return None
        left_mps, right_mps = driver.command_at(t_s)
        return round(left_mps * 1000) / 1000.0, round(right_mps * 1000) / 1000.0

    def _nodes(self) -> list[BusNode]:
        nodes: list[BusNode] = [self.motor_controller, self.truth]
        return nodes if self.driver is None else [*nodes, self.driver]

    @property
    def frames_sent(self) -> int:
        """Frames the nodes put on the bus."""
        return sum(node.frames_sent for node in self._nodes())

    @property
    def tx_errors(self) -> int:
        """Frames the bus refused."""
        return sum(node.tx_errors for node in self._nodes())


def _send_data(bus: OdocanBus, stamp_s: float, can_id: int, data: bytes) -> None:
    """``bus.send_data`` with ``_Wire.deliver_data``'s arguments (a closed handle refuses it,
    one not preserving timestamps stamps the wall clock's time)."""
    bus.send_data(can_id, data, stamp_s)
