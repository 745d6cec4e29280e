"""``TickPlan``: the sim node's frames of a lookahead block, packed at once (issue #13).

While ``sim.lookahead.PlannedVehicle`` runs a scenario's open-loop drive a block of ticks ahead,
everything the sim node (``sim.motor_controller.SimNode``) will send in those ticks is known: the
driver's MOTOR_CMD (the forecast's commands), WHEEL_ENCODERS (the block's counts) and SIM_TRUTH
(the block's truth), each with the COUNTER its node will have reached. ``plan_ticks`` computes
their payloads for the rest of the block in one batch (the words in Python, the Profile 2 CRCs
and the bytes in numpy: ``seal_words``), and ``SimNode.tick`` sends a tick's frames from the plan
while it holds, making the same calls on the vehicle and the motor controller's E2E receiver as
the plain tick (``MotorController.deliver``, ``Vehicle.advance_to``).

A plan holds for tick k only as the plain tick would have computed its frames: the same driver,
scenario and vehicle block, the clock at the tick's time, the nodes' counters where the plan
left them (a restart or any send in between shows there), and nothing waiting on the sim's bus
handle (a MOTOR_CMD from elsewhere). Otherwise the plain tick runs and the plan is dropped for
the rest of its block (a miss costs time, never a bit); ``tests/test_sim_plan.py`` compares the
logs of rigs with and without it, across a miss.

A value a packer would saturate (a command beyond the i16 mm/s range, a truth beyond the i32
0.1 mm range) ends the plan before its tick: the plain tick then sets the node's SATURATION bit.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from odocan.firmware import frames as fr
from odocan.firmware.e2e import CRC8H2F_INIT, CRC8H2F_TABLE, CRC8H2F_XOR_OUT
from odocan.firmware.fixmath import I16_MAX, I16_MIN, I32_MAX, I32_MIN
from odocan.sim.frames import SimTruthPart

if TYPE_CHECKING:
    from odocan.sim.lookahead import PlannedVehicle
    from odocan.sim.motor_controller import MotorController, SimNode

_U24 = 0xFF_FFFF
_BAM16_PER_RAD = 65536 / (2 * math.pi)  # as sim.motor_controller's TruthSender
_CRC_TABLE = np.array(CRC8H2F_TABLE, dtype=np.uint8)


class PlannedTick(NamedTuple):
    """One tick's frames and the node counters it starts from."""

    t_s: float  # the clock's time at the tick
    counters: tuple[int, int, int]  # (driver, motor controller, truth) COUNTER before the tick
    # the driver's MOTOR_CMD payload and its speeds as the motor controller decodes them (m/s)
    motor_cmd: tuple[bytes, tuple[float, float]] | None
    wheel_encoders: bytes
    sim_truth: tuple[bytes, ...]  # the SIM_TRUTH parts X, Y, HEADING (empty: none this tick)


class TickPlan:
    """Ticks ``first ..`` of one vehicle block (``ticks[k - first]``)."""

    __slots__ = ("block", "driver", "first", "offset", "scenario", "ticks")

    def __init__(self, node: SimNode, block: object, first: int) -> None:
        self.block = block
        self.driver = node.driver
        self.scenario = None if node.driver is None else node.driver.scenario
        self.offset = node.motor_controller._count_offset
        self.first = first
        self.ticks: list[PlannedTick] = []

    def at(self, node: SimNode, k: int) -> PlannedTick | None:
        """Tick ``k``'s frames when the plan holds for it (module docstring), else None."""
        i = k - self.first
        if not 0 <= i < len(self.ticks):
            return None
        tick = self.ticks[i]
        driver, mc = node.driver, node.motor_controller
        vehicle: PlannedVehicle = node.vehicle  # type: ignore[assignment]
        if (
            driver is not self.driver
            or (driver is not None and driver.scenario is not self.scenario)
            or mc._count_offset is not self.offset
            or not vehicle.serves(self.block)
            or node.clock.now_s() != tick.t_s
            or node.bus._queue  # type: ignore[attr-defined]
            or (-1 if driver is None else driver.counter, mc.counter, node.truth.counter)
            != tick.counters
        ):
            return None
        return tick


def seal_words(words: np.ndarray | list[int], data_ids: tuple[int, ...]) -> list[bytes]:
    """``firmware.frames.seal_frame`` of many words at once: each frame's Profile 2 CRC in byte
    0 (CRC8H2F over bytes 1..7, then the data ID of its COUNTER), as 8-byte payloads."""
    if len(words) == 0:
        return []
    raw = np.asarray(words, dtype="<u8").view(np.uint8).reshape(len(words), 8).copy()
    table = _CRC_TABLE
    crc = table[CRC8H2F_INIT ^ raw[:, 1]]
    for column in range(2, 8):
        crc = table[crc ^ raw[:, column]]
    ids = np.array(data_ids, dtype=np.uint8)[raw[:, 1] & 0x0F]
    raw[:, 0] = table[crc ^ ids] ^ CRC8H2F_XOR_OUT
    flat = raw.tobytes()
    return [flat[i : i + 8] for i in range(0, len(flat), 8)]


def plan_ticks(node: SimNode, vehicle: PlannedVehicle, k: int) -> TickPlan | None:
    """The sim node's frames from tick ``k`` to the end of the vehicle's block (None: the
    vehicle does not run ahead at tick ``k``, or no tick can be planned)."""
    ahead = vehicle.block_ahead(k, node.clock.now_s())
    if ahead is None:
        return None
    block, counts = ahead
    plan = TickPlan(node, block, k)
    times = vehicle.tick_times(k, len(counts))
    cmds, truths = _commands(node, k, times), _truths(node, vehicle, k, times)
    ticks = min(len(cmds), len(truths))  # up to the first value a packer would saturate
    if ticks == 0:
        return None
    mc = node.motor_controller
    encs = seal_words(_encoder_words(mc, vehicle, counts[:ticks]), fr.WHEEL_ENCODERS_DATA_IDS)
    cmd_words = [c[0] for c in cmds[:ticks] if c is not None]
    cmd_frames = iter(seal_words(cmd_words, fr.MOTOR_CMD_DATA_IDS))
    truth_words = [w for t in truths[:ticks] for w in t]
    truth_frames = iter(seal_words(truth_words, fr.SIM_TRUTH_DATA_IDS))
    c_drv = -1 if node.driver is None else node.driver.counter
    c_mc, c_truth = mc.counter, node.truth.counter
    for i in range(ticks):
        command = cmds[i]
        cmd = None if command is None else (next(cmd_frames), command[1])
        parts = (next(truth_frames), next(truth_frames), next(truth_frames)) if truths[i] else ()
        plan.ticks.append(PlannedTick(times[i], (c_drv, c_mc, c_truth), cmd, encs[i], parts))
        c_drv = c_drv if cmd is None else (c_drv + 1) & 0xF
        c_mc = (c_mc + 1) & 0xF
        c_truth = (c_truth + 3) & 0xF if parts else c_truth
    return plan


_Command = tuple[int, tuple[float, float]] | None


def _commands(node: SimNode, k: int, times: list[float]) -> list[_Command]:
    """Per tick from ``k``: the driver's MOTOR_CMD word (None: none this tick) and its speeds as
    ``MotorController.deliver`` decodes them (m/s), until one the plan cannot make (the
    forecast did not take it, or a speed would saturate)."""
    driver = node.driver
    if driver is None:
        return [None] * len(times)
    ahead = driver._ahead if driver._ahead_of is driver.scenario else {}
    every = node._driver_ticks
    counter = driver.counter
    out: list[_Command] = []
    for i, t_s in enumerate(times):
        if (k + i) % every:
            out.append(None)
            continue
        command = ahead.get(t_s)
        if command is None:
            return out
        left, right = round(command[0] * 1000), round(command[1] * 1000)
        if not (I16_MIN <= left <= I16_MAX and I16_MIN <= right <= I16_MAX):
            return out
        counter = (counter + 1) & 0xF
        word = (counter << 8) | ((left & 0xFFFF) << 16) | ((right & 0xFFFF) << 32)
        out.append((word, (left / 1000.0, right / 1000.0)))
    return out


def _truths(
    node: SimNode, vehicle: PlannedVehicle, k: int, times: list[float]
) -> list[tuple[int, ...]]:
    """Per tick from ``k``: SIM_TRUTH's three words as ``TruthSender.send`` packs them (none
    off its cycle), until a tick whose X or Y would saturate."""
    every, phase = node._truth_ticks, node.truth_phase_ticks
    counter, enc_counter = node.truth.counter, node.motor_controller.counter
    out: list[tuple[int, ...]] = []
    for i, t_s in enumerate(times):
        enc_counter = (enc_counter + 1) & 0xF  # this tick's WHEEL_ENCODERS COUNTER
        if (k + i - phase) % every:
            out.append(())
            continue
        pose = vehicle.truth_at_time(t_s)
        x, y = round(pose.x_m * 1e4), round(pose.y_m * 1e4)
        if not (I32_MIN <= x <= I32_MAX and I32_MIN <= y <= I32_MAX):
            return out
        heading = round(pose.heading_rad * _BAM16_PER_RAD) & 0xFFFF
        raws = (x & 0xFFFF_FFFF, y & 0xFFFF_FFFF, heading)
        words = []
        parts = (SimTruthPart.X, SimTruthPart.Y, SimTruthPart.HEADING)
        for part, raw in zip(parts, raws, strict=True):
            counter = (counter + 1) & 0xF
            words.append((int(part) << 12) | (counter << 8) | (enc_counter << 16) | (raw << 24))
        out.append(tuple(words))
    return out


def _encoder_words(
    mc: MotorController, vehicle: PlannedVehicle, counts: list[tuple[int, int]]
) -> np.ndarray:
    """WHEEL_ENCODERS' words of ``counts`` as ``MotorController.sample_and_send`` packs them
    (its COUNTER from the next one on; the counts less the restart offset, to the counter's
    width and the wire's 24 bits)."""
    mask = ((1 << vehicle.profile.counter_bits) - 1) & _U24
    raw = np.array(counts, dtype=np.int64)
    offset = np.array(mc._count_offset, dtype=np.int64)
    masked = ((raw - offset) & mask).astype(np.uint64)
    counters = ((mc.counter + 1 + np.arange(len(counts))) & 0xF).astype(np.uint64)
    words: np.ndarray = (
        (counters << np.uint64(8))
        | (masked[:, 0] << np.uint64(16))
        | (masked[:, 1] << np.uint64(40))
    )
    return words
