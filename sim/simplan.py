"""``TickPlan``: the sim node's frames of a lookahead block, packed at once (issue #13).

While ``sim.lookahead.PlannedVehicle`` runs a scenario's open-loop drive a block of ticks ahead,
everything the sim node (``sim.motor_controller.SimNode``) will send in those ticks is known: the
driver's MOTOR_CMD (the forecast's commands), WHEEL_ENCODERS (the block's counts) and SIM_TRUTH
(the block's truth), each with the COUNTER its node will have reached. ``plan_ticks`` computes
their payloads for the rest of the block in one batch (the encoder and command words, the
Profile 2 CRCs and the bytes in numpy: ``seal_words``; the truth's words, 3 per 10 ticks, in
Python), and ``SimNode.tick`` sends a tick's frames from the plan while it holds, making the
same calls on the vehicle and the motor controller's E2E receiver as the plain tick
(``MotorController.deliver``, ``Vehicle.advance_to``).

A plan holds for tick k only as the plain tick would have computed its frames: its ticks in a
row, the same driver, scenario, restart offset and vehicle block, the clock at the tick's time,
the nodes' counters where its last tick left them (a restart or any send in between shows
there), and nothing waiting on the sim's bus handle (a MOTOR_CMD from elsewhere). Otherwise
the plain tick runs and the plan is dropped for the rest of its block (a miss costs time, never
a bit); ``tests/test_sim_plan.py`` compares the logs of rigs with and without it, across a miss
and a restart.

A value a packer would saturate (a command beyond the i16 mm/s range, a truth beyond the i32
0.1 mm range) ends the plan before its tick: the plain tick then sets the node's SATURATION bit.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from odocan.firmware.e2e import COUNTER_MASK, CRC8H2F_INIT, CRC8H2F_TABLE, CRC8H2F_XOR_OUT
from odocan.firmware.fixmath import I16_MAX, I16_MIN, I32_MAX, I32_MIN
from odocan.sim.frames import CTRL_UPTIME_MAX_S, ENC_COUNTER_START_BIT, SimTruthPart

if TYPE_CHECKING:
    from odocan.sim.lookahead import PlannedVehicle
    from odocan.sim.motor_controller import MotorController, SimNode

_U24 = 0xFF_FFFF
_BAM16_PER_RAD = 65536 / (2 * math.pi)  # as sim.motor_controller's TruthSender
_CRC_TABLE = np.array(CRC8H2F_TABLE, dtype=np.uint8)


class TickPlan:
    """Ticks ``first .. first + len(times) - 1`` of one vehicle block, tick ``k`` at index
    ``k - first`` of each list."""

    __slots__ = ("after", "block", "counters", "driver", "encoders", "first", "motor_cmds",
                 "next", "offset", "powered_up_s", "scenario", "substeps", "times", "truths")

    def __init__(self, node: SimNode, block: object, first: int) -> None:
        self.block = block
        self.driver = node.driver
        self.scenario = None if node.driver is None else node.driver.scenario
        self.offset = node.motor_controller._count_offset
        self.powered_up_s = node.motor_controller.powered_up_s  # CTRL_UPTIME's origin
        self.first = first
        self.next = 0  # the index of the next tick to send: the plan's ticks go in a row
        # (driver, motor controller, truth) COUNTER before the next tick (-1: none sent yet)
        self.counters = node_counters(node)
        self.times: list[float] = []  # the clock's time at the tick
        self.substeps: list[int] = []  # the vehicle's substep at the tick (the block's)
        # the driver's MOTOR_CMD payload and its speeds as the motor controller decodes them (m/s)
        self.motor_cmds: list[tuple[bytes, tuple[float, float]] | None] = []
        self.encoders: list[bytes] = []  # WHEEL_ENCODERS
        self.truths: list[tuple[bytes, ...]] = []  # SIM_TRUTH X, Y, HEADING (empty: none)
        self.after: list[tuple[int, int, int]] = []  # ``counters`` after each tick's sends

    def at(self, node: SimNode, k: int) -> int:
        """The index of tick ``k`` when the plan holds for it (module docstring), else -1. Runs
        every tick: the counters compared one by one (no tuple), the block by identity
        (``PlannedVehicle.serves``, inlined), the driver's checks only when there is one."""
        i = k - self.first
        if i != self.next or i >= len(self.times):
            return -1
        driver, mc = node.driver, node.motor_controller
        driver_counter, mc_counter, truth_counter = self.counters
        if (
            driver is not self.driver
            or mc._count_offset is not self.offset
            or mc.powered_up_s != self.powered_up_s
            or node.vehicle._block is not self.block  # type: ignore[attr-defined]
            or node.clock.now_s() != self.times[i]
            or node.bus._queue  # type: ignore[attr-defined]
            or mc.counter != mc_counter
            or node.truth.counter != truth_counter
        ):
            return -1
        if driver is not None and (
            driver.scenario is not self.scenario or driver.counter != driver_counter
        ):
            return -1
        return i


def node_counters(node: SimNode) -> tuple[int, int, int]:
    """The (driver, motor controller, truth) E2E COUNTERs of ``node`` (-1: none sent yet)."""
    driver = node.driver
    return (
        -1 if driver is None else driver.counter,
        node.motor_controller.counter,
        node.truth.counter,
    )


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
    ids = np.array(data_ids, dtype=np.uint8)[raw[:, 1] & COUNTER_MASK]
    raw[:, 0] = table[crc ^ ids] ^ CRC8H2F_XOR_OUT
    return raw.view("V8").ravel().tolist()  # bytes each


def plan_ticks(node: SimNode, vehicle: PlannedVehicle, k: int) -> TickPlan | None:
    """The sim node's frames from tick ``k`` to the end of the vehicle's block, or to the first
    value a packer would saturate (None: the vehicle does not run ahead at tick ``k``, or no
    tick can be planned)."""
    ahead = vehicle.block_ahead(k, node.clock.now_s())
    if ahead is None:
        return None
    block, counts, substeps = ahead
    times = vehicle.tick_times(k, len(counts))
    cmd_at = [] if node.driver is None else _due(k, len(times), node._driver_ticks, 0)
    truth_at = _due(k, len(times), node._truth_ticks, node.truth_phase_ticks)
    cmds = _commands(node, [times[i] for i in cmd_at])
    truths = _truths(node, vehicle, k, truth_at, times)
    ticks = min([len(times), *cmd_at[len(cmds) :][:1], *truth_at[len(truths) :][:1]])
    if ticks == 0:
        return None
    cmd_at, truth_at = cmd_at[: len(cmds)], truth_at[: len(truths)]
    mc = node.motor_controller
    plan = TickPlan(node, block, k)
    plan.times = times[:ticks]
    plan.substeps = substeps[:ticks]
    plan.encoders = seal_words(_encoder_words(mc, vehicle, counts[:ticks], plan.times),
                               mc.e2e.data_ids)
    plan.motor_cmds = [None] * ticks
    sealed = seal_words([word for word, _ in cmds], mc.cmd_e2e.data_ids)
    for i, (_, speeds), data in zip(cmd_at, cmds, sealed, strict=True):
        plan.motor_cmds[i] = (data, speeds)
    plan.truths = [()] * ticks
    sealed = seal_words([word for words in truths for word in words], node.truth.e2e.data_ids)
    for j, i in enumerate(truth_at):
        plan.truths[i] = tuple(sealed[3 * j : 3 * j + 3])
    plan.after = _counters_after(plan, (mc.cmd_e2e.counter_mask, mc.e2e.counter_mask,
                                        node.truth.e2e.counter_mask))
    return plan


def _counters_after(plan: TickPlan, masks: tuple[int, int, int]) -> list[tuple[int, int, int]]:
    """The (driver, motor controller, truth) COUNTERs after each tick of ``plan``, as the nodes'
    sends step them: the driver's by one a MOTOR_CMD, the motor controller's by one a tick, the
    truth's by three a SIM_TRUTH tick, each to its message's lap (``masks``: the DBC's)."""
    driver, mc, truth = plan.counters
    driver_mask, mc_mask, truth_mask = masks
    after = []
    for motor_cmd, sim_truth in zip(plan.motor_cmds, plan.truths, strict=True):
        if motor_cmd is not None:
            driver = (driver + 1) & driver_mask
        mc = (mc + 1) & mc_mask
        if sim_truth:
            truth = (truth + 3) & truth_mask
        after.append((driver, mc, truth))
    return after


def _due(k: int, ticks: int, every: int, phase: int) -> list[int]:
    """The indices ``i < ticks`` of the ticks ``k + i`` of a cycle of ``every`` ticks that
    falls on ticks ``k = phase`` (mod ``every``)."""
    return list(range((phase - k) % every, ticks, every))


def _commands(node: SimNode, times: list[float]) -> list[tuple[int, tuple[float, float]]]:
    """The driver's MOTOR_CMD word at each of ``times`` (its ticks) and the speeds as
    ``MotorController.deliver`` decodes them (m/s), up to one the plan cannot make (the
    forecast did not take it, or a speed would saturate): ``ScenarioDriver.send``'s
    ``round(speed * 1000)`` (half to even, as ``np.rint``) and ``i16 / 1000.0``, in numpy."""
    driver = node.driver
    assert driver is not None
    ahead = driver._ahead if driver._ahead_of is driver.scenario else {}
    commands = []
    for t_s in times:
        command = ahead.get(t_s)
        if command is None:
            break
        commands.append(command)
    if not commands:
        return []
    mm_s = np.rint(np.array(commands, dtype=np.float64) * 1000)
    fits = (np.isfinite(mm_s) & (mm_s >= I16_MIN) & (mm_s <= I16_MAX)).all(axis=1)
    count = len(commands) if fits.all() else int(np.argmin(fits))
    raw = mm_s[:count].astype(np.int64)
    counters = (driver.counter + 1 + np.arange(count)) & driver.e2e.counter_mask
    words = (counters << 8) | ((raw[:, 0] & 0xFFFF) << 16) | ((raw[:, 1] & 0xFFFF) << 32)
    speeds = (raw / 1000.0).tolist()
    return [(word, (left, right)) for word, (left, right) in zip(words.tolist(), speeds,
                                                                 strict=True)]


def _truths(
    node: SimNode, vehicle: PlannedVehicle, k: int, due: list[int], times: list[float]
) -> list[tuple[int, int, int]]:
    """SIM_TRUTH's three words at ticks ``k + i`` for ``i`` in ``due``, as ``TruthSender.send``
    packs them, up to a tick whose X or Y would saturate."""
    counter, enc_counter = node.truth.counter, node.motor_controller.counter
    mask, enc_mask = node.truth.e2e.counter_mask, node.motor_controller.e2e.counter_mask
    echo = node.truth.enc_counter_mask
    xs, ys, headings = vehicle.truths_at([times[i] for i in due])
    out: list[tuple[int, int, int]] = []
    for i, x_m, y_m, heading_rad in zip(due, xs, ys, headings, strict=True):
        x, y = round(x_m * 1e4), round(y_m * 1e4)
        if not (I32_MIN <= x <= I32_MAX and I32_MIN <= y <= I32_MAX):
            return out
        heading = round(heading_rad * _BAM16_PER_RAD) & 0xFFFF
        # the tick's WHEEL_ENCODERS COUNTER, as ENC_COUNTER echoes it
        head = ((enc_counter + 1 + i) & enc_mask & echo) << ENC_COUNTER_START_BIT
        x_word = (SimTruthPart.X << 12) | (((counter + 1) & mask) << 8) | head | (
            (x & 0xFFFF_FFFF) << 24)
        counter = (counter + 1) & mask
        y_word = (SimTruthPart.Y << 12) | (((counter + 1) & mask) << 8) | head | (
            (y & 0xFFFF_FFFF) << 24)
        counter = (counter + 1) & mask
        h_word = (SimTruthPart.HEADING << 12) | (((counter + 1) & mask) << 8) | head | (
            heading << 24)
        out.append((x_word, y_word, h_word))
        counter = (counter + 1) & mask
    return out


def _encoder_words(
    mc: MotorController, vehicle: PlannedVehicle, counts: list[tuple[int, int]],
    times: list[float],
) -> np.ndarray:
    """WHEEL_ENCODERS' words of ``counts`` at ``times`` as ``MotorController.sample_and_send``
    packs them (its COUNTER from the next one on; the counts less the restart offset, to the
    counter's width and the wire's 24 bits; CTRL_UPTIME as ``sim.frames.ctrl_uptime_code``: the
    same IEEE subtraction, floor and saturation)."""
    mask = ((1 << vehicle.profile.counter_bits) - 1) & _U24
    raw = np.array(counts, dtype=np.int64)
    offset = np.array(mc._count_offset, dtype=np.int64)
    masked = ((raw - offset) & mask).astype(np.uint64)
    counters = ((mc.counter + 1 + np.arange(len(counts))) & mc.e2e.counter_mask).astype(np.uint64)
    age_s = np.array(times, dtype=np.float64) - mc.powered_up_s
    uptime = np.minimum(CTRL_UPTIME_MAX_S, 1 + np.floor(age_s)).astype(np.uint64)
    words: np.ndarray = (
        (counters << np.uint64(8))
        | (uptime << np.uint64(12))
        | (masked[:, 0] << np.uint64(16))
        | (masked[:, 1] << np.uint64(40))
    )
    return words
