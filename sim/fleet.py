"""A fleet: N independent robots in one process, stepped in real time by one timer loop.

Each robot is a ``sim.rig.LockstepRig`` of its own (the same node classes as the lockstep rig:
motor controller, ground truth, scenario driver, firmware board, host observer) on its own channel
of the in-process ``odocan`` transport (or python-can ``virtual``: ``FleetConfig.transport``),
with seed ``seed + index``. ``Fleet.step(k)`` runs tick ``k`` of every robot (simulated time
``k * 10 ms``: a robot's frames are those of the lockstep rig with its seed); the host observer's
frames are collected, tagged with the robot's index, for ``take_batch``: on the ``odocan``
transport as the ``(t, id, payload)`` tuples it queued (``sim.framebatch``; ``frame_fields``
reads either kind), a tick's at once, without a ``can.Message`` per frame.

Each robot's scenario drive runs ahead in blocks (``sim.lookahead``, ``FleetConfig.lookahead``:
the same frames for less CPU). A block's work comes at once, so a fleet's blocks are short
(``BLOCK_TICKS``: ~0.4 ms of CPU), the first blocks run when the fleet is built, before any clock,
and each robot's first block has its own length (``first_block_ticks``): robot ``i``'s later
blocks start on the fleet ticks ``block_phase(i)`` (``i * BLOCK_STRIDE``, mod ``BLOCK_TICKS``),
one robot's block in a tick for up to ``BLOCK_TICKS`` robots, never all at once, and a worker's
shard of consecutive robots spread over the whole period (before, robot ``i``'s came on tick
``i``: a 50-robot shard's blocks, ~1 ms of CPU each, one a tick through half of each second).

``run_realtime`` paces ``Fleet.step`` to the wall clock as one asyncio task: at each release
``k * period`` it sleeps until the release, accounts the tick's lateness (``DeadlineStats``: a
tick starting more than half a period after its release is late; releases a whole period or more
behind are skipped, never run in a burst: each robot sends their driver commands and encoder
samples late, each taken at its own release, ``Fleet.step``; a tick ``sim.board.HALT_AFTER_S``
or more after the previous one is run by every board as a halted MCU's, counted in
``Fleet.halts`` and ``Fleet.halted_from_s`` for the verdict), steps every robot, and hands the
tick's frames to ``on_batch`` (e.g. the MQTT bridge). Between ticks the event loop runs the
other tasks (MQTT I/O): one thread, no lock, no GIL contention with the timer.
"""

from __future__ import annotations

import asyncio
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from itertools import repeat

import can

from odocan.sim.board import HALT_AFTER_S, TICK_S
from odocan.sim.clock import RealTimeClock
from odocan.sim.closing import Closing
from odocan.sim.contract import cycle_ticks, database
from odocan.sim.framebatch import DataFrame, FrameBatchListener, Received
from odocan.sim.lookahead import PlannedVehicle
from odocan.sim.provision import robot_key
from odocan.sim.realtime import DeadlineStats, send_skipped_samples
from odocan.sim.releasegate import ReleaseGate
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.robot import RobotProfile

# (robot index, frame) in bus order per robot: a frame as its transport queued it (Received)
Batch = list[tuple[int, Received]]
_fleet_ids = iter(range(1 << 62))


def robot_name(index: int) -> str:
    """The name of robot ``index`` (0-based): ``robot001``, ``robot002``, ..."""
    return f"robot{index + 1:03d}"


@dataclass(frozen=True)
class FleetConfig:
    """N robots of one profile; robot i drives scenario ``scenario`` with seed ``seed + i``.

    A shard (``first`` > 0) holds robots ``first .. first + robots - 1`` of a larger fleet: their
    names, seeds, tick phases and so frames are those robots' in the whole fleet, so shards on
    several processes or machines never clash and a robot's bytes do not depend on the sharding."""

    robots: int
    robot: RobotProfile
    integrator: str = "exact"
    scenario: str = "random"
    seed: int = 0
    transport: str = "odocan"  # the rigs' python-can interface (sim.rig.TRANSPORTS)
    firmware: str = "python"  # every board's firmware (sim.cboard.FIRMWARES): python or c
    lookahead: bool = True  # the scenario drives run ahead in staggered blocks (sim.lookahead)
    first: int = 0  # fleet-wide index of this shard's first robot (names and seeds count on)
    # SecOC fleet key (None: no SecOC): each firmware gets its own key, sim.provision.robot_key
    secoc_key: bytes | None = field(default=None, repr=False)

    def shard(self, first: int, robots: int) -> FleetConfig:
        """Robots ``first .. first + robots - 1`` of this fleet (fleet-wide indices)."""
        return replace(self, first=self.first + first, robots=robots)


class _Collector(FrameBatchListener):
    """The host observer of robot ``index``: counts its frames and tags them into the batch.

    On the ``odocan`` transport a tick's frames arrive at once (``on_frames``) as the transport
    queued them, ``DataFrame`` tuples shared with no one else (no ``Message`` built); on
    ``virtual`` one ``Message`` at a time."""

    def __init__(self, index: int, batch: Batch) -> None:
        self.index = index
        self.batch = batch
        self.counts: Counter[int] = Counter()

    def on_frames(self, frames: list[Received]) -> None:
        self.counts.update([f[1] if type(f) is tuple else f.arbitration_id  # type: ignore[union-attr]
                            for f in frames])
        self.batch.extend(zip(repeat(self.index), frames))

    def on_message_received(self, msg: can.Message) -> None:
        self.counts[msg.arbitration_id] += 1
        self.batch.append((self.index, msg))


class Fleet(Closing):
    """N lockstep rigs stepped together (see the module docstring)."""

    def __init__(self, config: FleetConfig) -> None:
        if config.robots < 1:
            raise ValueError(f"a fleet needs at least one robot, got {config.robots}")
        self.config = config
        self.names = [robot_name(config.first + i) for i in range(config.robots)]
        self._batch: Batch = []
        self._collectors = [_Collector(i, self._batch) for i in range(config.robots)]
        prefix = f"odocan-fleet-{next(_fleet_ids)}"
        self.rigs = [
            LockstepRig(
                RigConfig(
                    robot=config.robot,
                    integrator=config.integrator,
                    scenario=config.scenario,
                    seed=config.seed + config.first + i,
                    channel=f"{prefix}-{i}",
                    truth_phase_ticks=_truth_phase(config.first + i),
                    transport=config.transport,
                    firmware=config.firmware,
                    lookahead=config.lookahead,
                    block_ticks=BLOCK_TICKS,
                    first_block_ticks=first_block_ticks(config.first + i),
                    secoc_key=None if config.secoc_key is None
                    else robot_key(config.secoc_key, self.names[i]),
                ),
                listeners=[self._collectors[i]],
            )
            for i in range(config.robots)
        ]
        self._planned = [rig.vehicle if isinstance(rig.vehicle, PlannedVehicle) else None
                         for rig in self.rigs]
        # each robot's tick loop (``LockstepRig.step``'s) and phase, read by every step
        self._loops = [(rig.loop, _tick_offset(config.first + i))
                       for i, rig in enumerate(self.rigs)]
        for vehicle in self._planned:  # every first block now, before any clock runs
            if vehicle is not None:
                vehicle.start()
        self._last_k = -1  # the latest tick stepped
        self._calm_since = 0  # the first tick stepped after the latest halt
        self.halts = 0  # ticks that came so late that every board was halted (``halted_from_s``)
        self.halted_from_k: int | None = None  # the fleet tick of the first of them
        self.halt_ticks: list[int] = []  # every such tick (one int a halt: <= 10 a second)
        self.halt_gaps: list[int] = []  # ... and the periods since the tick run before it
        self.longest_gap_periods = 1  # the most periods between two ticks stepped

    def step(self, k: int) -> None:
        """Tick ``k`` of every robot (simulated time ``k * TICK_S``). A robot whose drive fell
        back from running ahead (a recurring halt's gap: ``_isolated_halt``) runs ahead
        again from its next block tick (``PlannedVehicle.replan``) once ``BLOCK_TICKS`` ticks
        ran without a halt: a loop that keeps halting would pay blocks and fall backs for
        nothing (a skip that halts nothing no longer costs a plan). After skipped releases
        each robot first sends their driver commands and encoder samples (``_sample_skipped``:
        a drive run ahead serves them, it holds)."""
        if k != self._last_k + 1:
            if self._halts_boards(k):
                self._calm_since = k
            self._sample_skipped(k)
            self._count_halt(k)
        self._last_k = k
        first = self.config.first
        planned, calm = self._planned, k - self._calm_since >= BLOCK_TICKS
        for index, (loop, offset) in enumerate(self._loops):
            own_k = k - offset
            if own_k >= 0:
                vehicle = planned[index]
                if calm and vehicle is not None and vehicle.fell_back \
                        and (k - block_phase(first + index)) % BLOCK_TICKS == 0:
                    vehicle.replan(own_k * TICK_S, BLOCK_TICKS)
                loop.ticks = own_k  # ``rig.ticks = own_k; rig.step()``, two calls a robot less
                loop.tick(own_k)
                loop.ticks = own_k + 1

    def _count_halt(self, k: int) -> None:
        """Tick ``k`` comes ``k - _last_k`` periods after the previous one: from
        ``HALT_AFTER_S`` on every robot's board runs it as a halted MCU's (``sim.board``: its
        receive FIFO kept 3 frames and overran the rest, the firmware lost time). Counted here,
        where the loop knows it starved its robots: the frames the firmwares lost are not on
        the bus, so the judges cannot follow their poses from then (``halted_from_s``)."""
        gap = k - self._last_k
        self.longest_gap_periods = max(self.longest_gap_periods, gap)
        if not self._halts_boards(k):
            return
        self.halts += 1
        self.halt_gaps.append(gap)  # before the tick: a reader of halt_ticks finds its gap
        self.halt_ticks.append(k)
        if self.halted_from_k is None:
            self.halted_from_k = k

    def halted_from_s(self, index: int) -> float | None:
        """Bus time (s, robot ``index``'s own clock) of the first tick at which the loop had
        fallen so far behind that its board was halted (None: never): from then its firmware
        may have lost frames to the overrun that no judge saw it lose."""
        if self.halted_from_k is None:
            return None
        return max(self.halted_from_k - _tick_offset(self.config.first + index), 0) * TICK_S

    def offset_ticks(self, index: int) -> int:
        """How many fleet ticks robot ``index``'s clock starts late (its bus time of fleet tick
        k: ``(k - offset) * TICK_S``)."""
        return _tick_offset(self.config.first + index)

    def _sample_skipped(self, k: int) -> None:
        """Releases ``_last_k + 1 .. k - 1`` were skipped: each robot's motor controller sampled
        its encoders at each of them in hardware, so their frames go out now, each taken at its
        own release, back to back (COUNTER +1 each, as ``odocan sim`` does). Stepped straight
        to ``k``, a robot put several periods of motion under one COUNTER step, which its
        firmware rightly refused as faster than the robot can go (kobuki: IMPLAUSIBLE_STEP,
        COUNTER_RESET) or integrated as one long step. The scenario driver's commands of those
        releases go out too, each before its release's sample (``SimNode.drive_skipped``): the
        drive is open loop, a function of time, so the robot moves as without the skip and a
        drive run ahead serves them from its block (it does not fall back).
        A gap that halts the boards (``_count_halt``) sends the samples alone, as before: the
        halt judges model what a halted MCU's receive FIFO kept from those frames, and with the
        commands in the gap a firmware shifting 0.1 LSB at every halt PASSed
        (tests/test_fleet_halt_carry.py); the robot keeps its latest command through the gap.
        At an isolated halt (``_isolated_halt``) a drive run ahead is told so
        (``SimNode.hold_halted``): it stays planned; at a halt that recurs it falls back."""
        first, halted = self.config.first, self._halts_boards(k)
        hold = halted and self._isolated_halt(k)
        for index, rig in enumerate(self.rigs):
            offset = _tick_offset(first + index)
            skipped = range(max(self._last_k + 1 - offset, 0), max(k - offset, 0))
            if halted:
                if hold:
                    rig.sim.hold_halted(skipped)
                send_skipped_samples(rig.sim, rig.clock, skipped)
                continue
            clock, drive_skipped = rig.clock, rig.sim.drive_skipped
            for j in skipped:
                clock.advance_to(j * TICK_S)
                drive_skipped(j)

    def _isolated_halt(self, k: int) -> bool:
        """The halt before tick ``k`` is the first, or ``HOLD_CALM_TICKS`` or more after the
        previous one: worth keeping the drives planned through (``SimNode.hold_halted``). A
        hold runs the rest of each robot's block again and plans its frames anew (callgrind,
        pmir, C firmware: ~1.3 M instructions a robot plus ~66 k a tick run again); a drive
        that falls back instead runs plain (+~32 k a tick against a planned one) until a
        block's ticks pass without a halt. Once halts recur within ~1.5 s, the plain drive is
        the cheaper (a hold at every halt 30 ticks apart: 227.5 k -> 316.9 k instructions a
        robot-tick; ``bench/fleet_skips.py``, docs/mqtt.md "halts")."""
        ticks = self.halt_ticks
        return not ticks or k - ticks[-1] >= HOLD_CALM_TICKS

    def _halts_boards(self, k: int) -> bool:
        """Tick ``k`` comes so long after the previous one that every board runs it halted."""
        return self._last_k >= 0 and (k - self._last_k) * TICK_S >= HALT_AFTER_S

    def take_batch(self) -> Batch:
        """The frames the host observers saw since the last call, in bus order per robot."""
        batch = list(self._batch)
        self._batch.clear()
        return batch

    def host_bus(self, index: int) -> can.BusABC:
        """Robot ``index``'s host bus handle (send commands to its firmware on it)."""
        return self.rigs[index].host_bus

    def frame_counts(self, index: int) -> dict[str, int]:
        """Frames robot ``index``'s host observer saw, per message name."""
        names = {m.frame_id: m.name for m in database().messages}
        counts = self._collectors[index].counts
        return {names.get(i, hex(i)): n for i, n in sorted(counts.items())}

    def close(self) -> None:
        """Release every robot's buses."""
        for rig in self.rigs:
            rig.close()


def frame_fields(frame: Received) -> DataFrame:
    """``(timestamp s, identifier, payload)`` of a batch's frame, a ``DataFrame`` or a
    ``Message`` (of a classic data frame: a ``DataFrame`` drops the other flags)."""
    if type(frame) is tuple:
        return frame
    assert isinstance(frame, can.Message)
    return frame.timestamp, frame.arbitration_id, bytes(frame.data)


def _tick_offset(index: int) -> int:
    """Robot ``index`` (fleet-wide) starts this many fleet ticks late: every other robot runs one
    tick out of phase, so the pose, twist and MOTOR_CMD frames (every 2nd tick) of half the fleet
    fall on the other ticks. Each robot's own timeline is an ordinary rig's."""
    return index % 2


BLOCK_TICKS = 100  # a fleet's blocks run ahead (sim.lookahead: ~4 us of CPU a tick, at once)
BLOCK_STRIDE = 37  # consecutive robots' blocks this many ticks apart (coprime with BLOCK_TICKS)


def block_phase(index: int) -> int:
    """The fleet tick (mod ``BLOCK_TICKS``) on which robot ``index``'s (fleet-wide) blocks
    start: consecutive robots ``BLOCK_STRIDE`` ticks apart, every robot of the first
    ``BLOCK_TICKS`` on a tick of its own, and any run of consecutive robots (a worker's shard)
    spread over the period: 50 of them at most 6 in any 10 ticks."""
    return index * BLOCK_STRIDE % BLOCK_TICKS


HOLD_CALM_TICKS = 2 * BLOCK_TICKS  # a halt this long after the previous one keeps drives planned


def first_block_ticks(index: int) -> int:
    """The length (ticks, 1 .. ``BLOCK_TICKS``) of robot ``index``'s (fleet-wide) first block of
    its drive run ahead, such that its later blocks start on the fleet ticks ``block_phase``
    (mod ``BLOCK_TICKS``): its own tick plus its phase (``_tick_offset``)."""
    return (block_phase(index) - _tick_offset(index) - 1) % BLOCK_TICKS + 1


def _truth_phase(index: int) -> int:
    """Robot ``index``'s SIM_TRUTH tick in its own timeline: pairs of robots take turns (the
    truth is the costly part of a step), on even ticks so it stays aligned with the pose frames."""
    cycle = cycle_ticks("SIM_TRUTH", TICK_S)
    return (2 * (index // 2)) % cycle if cycle > 1 else 0


async def run_realtime(
    fleet: Fleet,
    *,
    duration_s: float | None,
    on_batch: Callable[[Batch], None] | None = None,
    stop: asyncio.Event | None = None,
    period_s: float = TICK_S,
    stats: DeadlineStats | None = None,
    gate: ReleaseGate | None = None,
) -> DeadlineStats:
    """Step ``fleet`` every ``period_s`` of the wall clock for ``duration_s`` (None: until
    ``stop``); returns the deadline accounting (see the module docstring), kept in ``stats``
    when given (so another task can watch it while the fleet runs); ``gate`` is told each
    release before the wait for it (``sim.releasegate``)."""
    clock = RealTimeClock()
    if stats is None:
        stats = DeadlineStats(period_s, period_s / 2)
    k = 0
    while stop is None or not stop.is_set():
        release = k * period_s
        if duration_s is not None and release >= duration_s - 1e-9:
            break
        delay = release - clock.now_s()
        if gate is not None:
            gate.next_s = time.monotonic() + delay
        await asyncio.sleep(max(delay, 0.0))  # 0: still let the MQTT tasks run once
        lateness = max(clock.now_s() - release, 0.0)
        if lateness >= period_s:
            missed = int(lateness / period_s)
            stats.skipped_releases += missed
            k += missed
        stats.record(lateness)
        fleet.step(k)
        batch = fleet.take_batch()
        if on_batch is not None:
            on_batch(batch)
        k += 1
    return stats
