"""Test helpers for the fault tests: a lockstep harness with fault-injecting bus handles, a pose
audit against the float64 reference, the catalogue of every protected frame, a binomial bound.

``FaultRig`` is ``sim.rig.LockstepRig`` rebuilt from the same classes in the same tick order, with
a ``FaultInjectingBus`` around the sim handle and/or the firmware handle (the change proposed for
``RigConfig.faults``), and the firmware MCU's stall and reboot of ``fw_faults`` stepped by
``sim.mcufaults.McuFaults`` as ``LockstepRig`` steps them (``halted`` and ``before_board`` hooks
add a test's own). Each tick's host frames go to the rig's observers.
"""

from __future__ import annotations

import math
import random
import tracemalloc
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from functools import partial

import can
import numpy as np

from odocan.firmware import frames as fr
from odocan.firmware.config import Integrator, RobotParams
from odocan.firmware.e2e import E2EReceiver, E2EStatus, p02_crc
from odocan.firmware.ecu import OdomEcu
from odocan.firmware.errors import ErrorMask
from odocan.firmware.hal import MAILBOX_SLOTS
from odocan.host.judge.reference import deltas_from_counts, integrate
from odocan.sim import frames as sf
from odocan.sim.board import TICK_S, TX_LATENCY_S, FirmwareBoard
from odocan.sim.cboard import board_maker
from odocan.sim.clock import LockstepClock
from odocan.sim.contract import database
from odocan.sim.faults import FaultInjectingBus, FaultSpec, catch_up, release_due
from odocan.sim.mcufaults import mcu_faults
from odocan.sim.motor_controller import SimNode
from odocan.sim.robot import RobotProfile, load
from odocan.sim.scenarios import RandomScenario, Scenario
from odocan.sim.tickloop import TickLoop
from odocan.sim.vehicle import Vehicle
from tests import host_frames as hf
from tests.dbc_typed import dbc_attribute
from tests.odo_helpers import geometry, params

Observer = Callable[[int, list[can.Message]], None]
Hook = Callable[[int], None]


def open_virtual(channel: str) -> can.BusABC:
    """A handle on a python-can virtual channel, keeping the senders' simulated timestamps."""
    return can.Bus(
        interface="virtual", channel=channel, preserve_timestamps=True, receive_own_messages=False
    )


def unique_channel(prefix: str = "odocan-faults") -> str:
    """A virtual channel no other test shares."""
    return f"{prefix}-{uuid.uuid4().hex}"


def robot_params(profile: RobotProfile, integrator: str) -> RobotParams:
    """The firmware's integers for ``profile`` (as ``sim.rig.firmware_params``)."""
    return RobotParams(**profile.firmware_params(), integrator=int(Integrator[integrator.upper()]))


class FaultRig:
    """Motor controller, truth, scenario driver, firmware board and host observer in lockstep."""

    def __init__(
        self,
        *,
        sim_faults: FaultSpec | None = None,
        fw_faults: FaultSpec | None = None,
        scenario: Scenario | None = None,
        robot: str = "pmir",
        integrator: str = "exact",
        seed: int = 0,
        firmware: str = "python",
    ) -> None:
        self.channel = unique_channel()
        self.clock = LockstepClock()
        self.profile = load(robot)
        self.params = robot_params(self.profile, integrator)
        self.integrator = integrator
        self.vehicle = Vehicle(self.profile, seed=seed)
        self._raw = [open_virtual(self.channel) for _ in range(3)]
        sim_raw, fw_raw, self.host_bus = self._raw
        self.sim_bus = FaultInjectingBus(sim_raw, sim_faults) if sim_faults else sim_raw
        bus_faults = None if fw_faults is None else fw_faults.bus_part()
        wrap = bus_faults is not None and (bus_faults.active or bus_faults == fw_faults)
        self.fw_bus = FaultInjectingBus(fw_raw, bus_faults) if wrap and bus_faults else fw_raw
        self.mcu = mcu_faults(fw_faults)  # the MCU's stall and reboot, as LockstepRig's
        self.sim = SimNode(self.sim_bus, self.vehicle, self.clock, scenario or RandomScenario(seed))
        board = board_maker(firmware)  # the C port: the same board around firmware/c
        self.board: FirmwareBoard = board(self.fw_bus, self.params, self.clock)
        self.observers: list[Observer] = []
        self.before_board: list[Hook] = []
        self._heard: list[can.Message] = []
        self.loop = TickLoop(self._work, self.host_bus, [_Heard(self._heard)], self.clock)
        self.halted: Callable[[int], bool] = lambda _k: False  # the MCU runs no tick (a stall)

    @property
    def ecu(self) -> OdomEcu:
        """The firmware."""
        return self.board.ecu

    @property
    def ticks(self) -> int:
        """Ticks run so far."""
        return self.loop.ticks

    def step(self) -> None:
        """One 10 ms tick of ``sim.tickloop`` as ``LockstepRig.step`` runs it (hooks run just
        before the board; the board does not run in ticks where ``halted(k)``); then the
        observers get the tick's host frames."""
        k = self.loop.ticks
        self.loop.step()
        frames = list(self._heard)
        self._heard.clear()
        for observer in self.observers:
            observer(k, frames)

    def _work(self, k: int) -> None:
        """As ``LockstepRig._work``: the faulted handles' babble and held frames go on the bus
        when due, in time order across both (``sim.faults.catch_up``, ``release_due``), not when
        their node next sends (babble then went out after the other node's later frames)."""
        if self.mcu is not None:  # a reset before the tick's frames (``sim.mcufaults``)
            self.mcu.before_nodes(self.board, k)
        faulted = [b for b in (self.sim_bus, self.fw_bus) if isinstance(b, FaultInjectingBus)]
        catch_up(faulted, self.clock.now_s())
        self.sim.tick(k)
        release_due(faulted, self.clock.now_s() + TX_LATENCY_S)
        for hook in self.before_board:
            hook(k)
        if not self.halted(k) and (self.mcu is None or self.mcu.runs(k)):
            self.board.run_tick()

    def mute_sim(self, ticks: range) -> None:
        """The motor controller silent in ``ticks`` (its tick not run: no frame, no counter
        advance on the bus; the firmware runs on)."""
        tick = self.sim.tick

        def muted_tick(k: int) -> None:
            if k not in ticks:
                tick(k)

        self.sim.tick = muted_tick  # type: ignore[method-assign]

    def run(self, duration_s: float) -> None:
        """``duration_s`` of simulated time."""
        for _ in range(round(duration_s / TICK_S)):
            self.step()

    def close(self) -> None:
        """Release every bus handle (the wrappers shut their wrapped bus down)."""
        for bus in (self.sim_bus, self.fw_bus, self.host_bus):
            bus.shutdown()

    def __enter__(self) -> FaultRig:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class _Heard(can.Listener):
    """Keeps every frame the host observer hears, in bus order."""

    def __init__(self, into: list[can.Message]) -> None:
        self.into = into

    def on_message_received(self, msg: can.Message) -> None:
        self.into.append(msg)


@dataclass
class PoseAudit:
    """The on-board pose, as the host sees it, against the float64 reference.

    Replays the firmware's WHEEL_ENCODERS acceptance on the host's copy of the bus (same filter,
    same Profile 2 check, ``check(None)`` in a tick without an encoder frame), integrates the
    accepted counts with ``host.reference.integrate`` and compares every ODOM_POSE_X/Y (those with
    a valid CRC: a babbling node may send on their IDs) with the reference after the frames
    accepted before it. Errors are in LSBs of the pose signals.
    """

    params: RobotParams
    integrator: str
    rx: E2EReceiver = field(default_factory=lambda: E2EReceiver(fr.WHEEL_ENCODERS_DATA_IDS))
    counts: list[tuple[int, int]] = field(default_factory=list)
    pose_x: list[tuple[int, int, int]] = field(default_factory=list)  # (accepted, X, HEADING)
    pose_y: list[tuple[int, int]] = field(default_factory=list)  # (accepted, Y)

    def __call__(self, tick: int, frames: list[can.Message]) -> None:
        encoder_seen = False
        for msg in frames:
            if msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id:
                continue
            data = bytes(msg.data)
            if msg.arbitration_id == fr.WHEEL_ENCODERS_ID:
                encoder_seen = True
                self._encoder(data)
            elif msg.arbitration_id == fr.ODOM_POSE_X_ID and _crc_ok(data, fr.ODOM_POSE_X_DATA_IDS):
                pose = hf.unpack_odom_pose_x(data)
                self.pose_x.append((len(self.counts), pose.x_100um, pose.heading_bam16))
            elif msg.arbitration_id == fr.ODOM_POSE_Y_ID and _crc_ok(data, fr.ODOM_POSE_Y_DATA_IDS):
                self.pose_y.append((len(self.counts), hf.unpack_odom_pose_y(data).y_100um))
        if not encoder_seen:
            self.rx.check(None)

    def _encoder(self, data: bytes) -> None:
        if len(data) != 8:
            return
        status = self.rx.check(data)
        if status is E2EStatus.OK or status is E2EStatus.OKSOMELOST:
            frame = fr.unpack_wheel_encoders(data)
            self.counts.append((frame.left_count, frame.right_count))

    def max_errors_lsb(self) -> tuple[float, float, float, int]:
        """(max |X err|, max |Y err|, max |HEADING err|, poses compared); X, Y in 0.1 mm LSBs,
        HEADING in BAM16 LSBs."""
        ref_x, ref_y, ref_h = self._reference()
        ex = eh = ey = 0.0
        for n, x, heading in self.pose_x:
            ex = max(ex, abs(x - ref_x[n]))
            d = (heading - ref_h[n]) % 65536.0
            eh = max(eh, min(d, 65536.0 - d))
        for n, y in self.pose_y:
            ey = max(ey, abs(y - ref_y[n]))
        return ex, ey, eh, len(self.pose_x) + len(self.pose_y)

    def _reference(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Reference pose after n accepted frames (n = 0, 1: the origin), in signal LSBs."""
        bits = min(self.params.counter_bits, 24)
        counts = np.array(self.counts, dtype=np.int64).reshape(-1, 2)
        poses = integrate(
            deltas_from_counts(counts[:, 0], bits),
            deltas_from_counts(counts[:, 1], bits),
            geometry(self.params),
            self.integrator,
        )
        zero = np.zeros(2)
        return (
            np.concatenate((zero, poses.x_m * 1e4)),
            np.concatenate((zero, poses.y_m * 1e4)),
            np.concatenate((zero, poses.heading_rad * (65536 / (2 * math.pi)))),
        )


def _crc_ok(data: bytes, data_ids: tuple[int, ...]) -> bool:
    """The host's check of a received pose frame (a babbling node may use the ID too)."""
    return len(data) == 8 and data[0] == p02_crc(data, data_ids[data[1] & 0xF])


# --- every protected frame of the DBC ----------------------------------------------------------
def _firmware_packers() -> dict[tuple[str, int | None], Callable[[int], bytes]]:
    """Frames packed by ``firmware.frames`` with typical values, by (message, mux value)."""
    e = ErrorMask()
    packers: dict[tuple[str, int | None], Callable[[int], bytes]] = {
        ("WHEEL_ENCODERS", None): lambda c: sf.pack_wheel_encoders(c, 0x12_3456, 0xAB_CDEF),
        ("MOTOR_CMD", None): lambda c: fr.pack_motor_cmd(c, 512, -300, e),
        ("ODOM_POSE_X", None): lambda c: fr.pack_odom_pose_x(c, 5, 123_456, 0x4000, e),
        ("ODOM_POSE_Y", None): lambda c: fr.pack_odom_pose_y(c, 6, -98_765, -2, e),
        ("ODOM_TWIST", None): lambda c: fr.pack_odom_twist(c, 7, 450, -120, 54_321, e),
        ("ODOM_ACK", None): lambda c: fr.pack_odom_ack(c, 3, fr.ODOM_CONFIG_ID, 2, 1, 1, e),
    }
    for f in fr.SetPoseField:
        packers["ODOM_SET_POSE", int(f)] = partial(
            hf.pack_odom_set_pose, field=f, value=7_654, errors=e
        )
    for p in fr.ConfigParam:
        value = (
            32 if p == fr.ConfigParam.COUNTER_BITS else 2 if p == fr.ConfigParam.INTEGRATOR else 75
        )
        packers["ODOM_CONFIG", int(p)] = partial(
            hf.pack_odom_config, param=p, value=value, errors=e
        )
    packers["ODOM_STATUS", 0] = lambda c: fr.pack_odom_status_summary(c, 1, 2, 0x0102, 3600, e)
    packers["ODOM_STATUS", 1] = lambda c: fr.pack_odom_status_frame_totals(c, 5, 6, 7)
    for page in range(2, 16):
        packers["ODOM_STATUS", page] = partial(
            fr.pack_odom_status_e2e, page=page, ok=1000, lost=1, repeated=2, crc_error=3,
            wrong_sequence=4,
        )
    packers["ODOM_STATUS", int(fr.StatusPage.PROFILE)] = lambda c: fr.pack_odom_status_profile(
        c, 4000, 0x12345678
    )
    for part in sf.SimTruthPart:
        packers["SIM_TRUTH", int(part)] = partial(
            sf.pack_sim_truth, part=part, enc_counter=9, value=-4321, errors=e
        )
    return packers


def dbc_frame_types() -> list[tuple[str, int | None]]:
    """Every (message, multiplexer value) of the DBC (None for a plain message); a multiplexer's
    values are those its signals use and those its VAL_ table names."""
    types: list[tuple[str, int | None]] = []
    for msg in database().messages:
        mux = next((s for s in msg.signals if s.is_multiplexer), None)
        if mux is None:
            types.append((msg.name, None))
            continue
        values = {v for s in msg.signals for v in (s.multiplexer_ids or ())}
        values |= {int(v) for v in (mux.choices or {})}  # pages without signals (APPLY)
        types.extend((msg.name, v) for v in sorted(values))
    return types


def protected_frames(counter: int) -> dict[tuple[str, int | None], tuple[int, bytes]]:
    """One valid frame (CAN ID, 8 bytes) of every DBC frame type with E2E ``counter``.

    Packed by ``firmware.frames`` where it has a packer; a message or page it does not pack yet
    is encoded by cantools from the DBC and sealed with the DBC's E2EDataIDs (so a page added to
    the DBC is covered at once).
    """
    packers = _firmware_packers()
    out: dict[tuple[str, int | None], tuple[int, bytes]] = {}
    for name, mux in dbc_frame_types():
        msg = database().get_message_by_name(name)
        packer = packers.get((name, mux))
        data = packer(counter) if packer else _cantools_frame(name, mux, counter)
        out[name, mux] = (msg.frame_id, data)
    return out


def dbc_data_ids(frame_id: int) -> tuple[int, ...]:
    """The message's Profile 2 DataIDList from the DBC's ``E2EDataIDs`` attribute."""
    attr = dbc_attribute(database().get_message_by_frame_id(frame_id), "E2EDataIDs")
    return tuple(int(v) for v in attr.split(","))


def _cantools_frame(name: str, mux: int | None, counter: int) -> bytes:
    msg = database().get_message_by_name(name)
    values: dict[str, int] = {}
    for s in msg.signals:
        if mux is not None and s.multiplexer_ids and mux not in s.multiplexer_ids:
            continue
        raw = 0xA5A5_A5A5_A5A5_A5A5 & ((1 << s.length) - 1)  # a pattern, raw
        if s.is_signed and raw >> (s.length - 1):
            raw -= 1 << s.length
        values[s.name] = raw
    values["COUNTER"] = counter
    values["CHECKSUM"] = 0
    mux_signal = next((s for s in msg.signals if s.is_multiplexer), None)
    if mux_signal is not None:
        assert mux is not None, name  # a multiplexed message is always asked for by page
        values[mux_signal.name] = mux
    data = bytearray(msg.encode(values, scaling=False, strict=False))
    data[0] = p02_crc(data, dbc_data_ids(msg.frame_id)[counter])
    return bytes(data)


# --- fuzzing -----------------------------------------------------------------------------------
SEALED_SHARE = 0.25  # fuzzed frames sealed with a valid CRC for an ID with a data-ID list


class CountingHal:
    """A CAN driver that only counts (no growing record)."""

    def __init__(self) -> None:
        self.sent = 0

    def transmit(self, can_id: int, data: bytes) -> bool:
        self.sent += 1
        return True


def random_frame(rng: random.Random) -> tuple[int, bool, bytes]:
    """(ID, extended, data): any ID and DLC, or (SEALED_SHARE) a CRC-valid frame of the DBC."""
    if rng.random() < SEALED_SHARE:
        can_id, ids = rng.choice(list(hf.DATA_IDS_BY_FRAME_ID.items()))
        data = bytearray(rng.randbytes(8))
        data[0] = p02_crc(data, ids[data[1] & 0xF])
        return can_id, False, bytes(data)
    extended = rng.random() < 0.4
    return rng.getrandbits(29 if extended else 11), extended, rng.randbytes(rng.randint(0, 8))


def burst_sizes(rng: random.Random, total: int) -> Iterator[int]:
    """Frames per tick adding up to ``total``: mostly a few, now and then a flood (overflow)."""
    left = total
    while left:
        n = rng.randint(40, 80) if rng.random() < 0.05 else rng.randint(0, 8)
        n = min(n, left)
        left -= n
        yield n


@dataclass
class EcuFuzz:
    """What ``fuzz_ecu`` did: the ECU, the mailbox overflows expected, memory grown (bytes)."""

    ecu: OdomEcu
    hal: CountingHal
    expected_overflows: int
    grown_bytes: int


def fuzz_ecu(n: int, seed: int) -> EcuFuzz:
    """``n`` random frames into ``OdomEcu.isr_can_rx`` in bursts, ``tick`` after each burst;
    the memory traced after the first 10 % of the frames is the baseline."""
    rng = random.Random(seed)
    hal = CountingHal()
    ecu = OdomEcu(hal, params("exact"))
    expected = 0
    tracemalloc.start()
    try:
        baseline = None
        done = 0
        for burst in burst_sizes(rng, n):
            for _ in range(burst):
                can_id, _, data = random_frame(rng)
                ecu.isr_can_rx(can_id, data)
            expected += max(0, burst - MAILBOX_SLOTS)
            ecu.tick()
            done += burst
            if baseline is None and done >= n // 10:
                baseline = tracemalloc.get_traced_memory()[0]
        grown = tracemalloc.get_traced_memory()[0] - (baseline or 0)
    finally:
        tracemalloc.stop()
    return EcuFuzz(ecu, hal, expected, grown)


def random_message(rng: random.Random, t_s: float) -> can.Message:
    """A data frame of ``random_frame``, or (10% each) an error frame or a remote frame."""
    u = rng.random()
    can_id, extended, data = random_frame(rng)
    if u < 0.1:
        return can.Message(timestamp=t_s, arbitration_id=can_id, is_error_frame=True, data=data)
    if u < 0.2:
        return can.Message(
            timestamp=t_s,
            arbitration_id=can_id,
            is_extended_id=extended,
            is_remote_frame=True,
            dlc=len(data),
        )
    return can.Message(timestamp=t_s, arbitration_id=can_id, is_extended_id=extended, data=data)


# --- statistics ---------------------------------------------------------------------------------
def binomial_upper_bound(k: int, n: int, confidence: float = 0.95) -> float:
    """Clopper-Pearson one-sided upper bound of a binomial rate after ``k`` events in ``n``."""
    alpha = 1.0 - confidence
    lo, hi = k / n, 1.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if _binomial_cdf(k, n, mid) > alpha:
            lo = mid
        else:
            hi = mid
    return hi


def _binomial_cdf(k: int, n: int, p: float) -> float:
    """P(X <= k), X ~ Binomial(n, p), summed in log space (k up to a few 10^4)."""
    if p <= 0.0:
        return 1.0
    if p >= 1.0:
        return 0.0 if k < n else 1.0
    log_p, log_q = math.log(p), math.log1p(-p)
    lgn = math.lgamma(n + 1)
    terms = [
        lgn - math.lgamma(i + 1) - math.lgamma(n - i + 1) + i * log_p + (n - i) * log_q
        for i in range(k + 1)
    ]
    top = max(terms)
    return math.exp(top) * sum(math.exp(t - top) for t in terms)


def reset_then_send(rig: FaultRig, reset_at: int, send_at: int | None,
                    frames: list[tuple[int, bytes]], ticks: int) -> tuple[can.Message, ...]:
    """Run ``rig`` ``ticks`` ticks: the MCU reset at tick ``reset_at`` (its receive FIFO
    cleared), ``frames`` (CAN ID, data) sent by a tool in tick ``send_at`` (a set-pose's or a
    config's staged fields and APPLY); every frame heard."""
    heard: list[can.Message] = []
    tool = open_virtual(rig.channel)

    def host(k: int) -> None:
        if k == reset_at:
            rig.board.reboot()
            while rig.fw_bus.recv(0) is not None:  # the reset clears the receive FIFO
                pass
        if k == send_at:
            for can_id, data in frames:
                tool.send(can.Message(arbitration_id=can_id, is_extended_id=False, data=data,
                                      timestamp=k * TICK_S))

    rig.observers.append(lambda _k, got: heard.extend(got))
    rig.before_board.append(host)
    try:
        rig.run(ticks * TICK_S)
    finally:
        tool.shutdown()
    return tuple(heard)
