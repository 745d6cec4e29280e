"""``PlannedVehicle``: an open-loop drive run a block of ticks ahead, its ground truth at once.

In a lockstep run driven by a scenario the motion is open loop: the wheel speeds are a function
of time (the scenario driver's MOTOR_CMD every 20 ms), the firmware steers nothing. The vehicle
can then be run ``BLOCK_TICKS`` ticks ahead with the commands the forecast predicts, through the
very same ``Drivetrain`` calls at the very same instants as the rig will make them (a command at
a driver tick, a sample at every tick), and its ground truth integrated over the whole block in
one batch (``GroundTruth.advance_folds``: sequential folds, bit-identical however batched; the
slip noise drawn in row order, the same stream). The rig's calls are then served from the block:
a command is checked against the forecast, a sample reads the counts recorded at its tick, a
truth request the folds at its substep. One numpy batch of 5000 substeps instead of one per
SIM_TRUTH (10 ticks, 100 substeps) is where the time goes down: numpy's cost per call, not per
element, was most of it (and the drive's wheel travel is taken as one array as well).

Whatever the forecast missed — a command it did not predict (the firmware or the host sent
MOTOR_CMD, a fault), a predicted one that did not come or came with other speeds, a time off the
tick grid, a read of the drivetrain's own state — the vehicle falls back for good: it restores
the state it had at the block's start (drivetrain, truth, the noise generator) and replays the
calls actually made since, then carries on as a plain ``Vehicle``. A forecast can cost time,
never a bit: the encoder counts and poses are those of the plain vehicle, call for call.

A block's work comes at once (~2 ms for 500 ticks): the rig uses it when asked
(``RigConfig(lookahead=True)``: ``odocan run``, ``bench/rig.py``). In real time (the fleet)
the blocks are shorter (``plan(block_ticks=...)``: a block's CPU is nearly all per tick), the
first is run before the clock starts (``start``) and its length differs per robot
(``first_block_ticks``), so the robots' later blocks fall on different ticks.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from odocan.sim.errors import ErrorModel
from odocan.sim.pose import wrap_angle
from odocan.sim.robot import RobotProfile
from odocan.sim.truth import TruthPose, TruthTrace
from odocan.sim.vehicle import _TIME_EPS, Vehicle, VehicleError

BLOCK_TICKS = 500  # ticks run ahead at once (5 s at 10 ms: 5000 substeps of truth in one batch)

Forecast = Callable[[int, float], tuple[float, float] | None]  # (tick, its time s) -> m/s or None
_Call = tuple[float, float, float] | float  # command (left m/s, right m/s, t s), advance_to(t s)


class _Block:
    """The ticks ``first .. first + BLOCK_TICKS - 1`` run ahead: what each call will read."""

    __slots__ = ("commands", "counts", "end", "folds", "heading", "index", "next_command",
                 "substeps", "truth_s0")

    def __init__(self) -> None:
        self.index: dict[int, int] = {}  # a tick's substep -> its position in ``counts``
        self.substeps: list[int] = []  # each tick's substep, in ``counts``' order
        self.counts: list[tuple[int, int]] = []  # encoder counts at each tick's substep
        self.commands: list[tuple[int, float, float]] = []  # (substep, left, right) predicted
        self.next_command = 0  # the first predicted command not yet made
        self.end = 0  # the substep of the block's last tick
        self.truth_s0 = 0  # the substep of the folds' index 0
        self.folds: Any = None  # (3, n + 1): x, y, distance (m) from truth_s0 on
        self.heading: Any = None  # (n + 1,): unwrapped heading (rad)


class PlannedVehicle(Vehicle):
    """A ``Vehicle`` that runs ahead of the rig while ``forecast`` predicts its commands.

    ``forecast(k, t_s)``: the (left, right) rim speeds (m/s, as ``Vehicle.command`` will get
    them) commanded at tick ``k`` (time ``t_s = start_s + k * tick_s``), or None when none is.
    Set it (``plan``) before the first call; until then, and after a fall back, the vehicle is a
    plain ``Vehicle``.
    """

    def __init__(
        self,
        profile: RobotProfile,
        errors: ErrorModel | None = None,
        seed: int = 0,
        quadrature: bool = False,
    ) -> None:
        super().__init__(profile, errors, seed=seed, quadrature=quadrature)
        self._forecast: Forecast | None = None
        self._tick_s = 0.0
        self._start_s = 0.0
        self._block: _Block | None = None
        self._next_tick = 0  # the first tick of the next block
        self._block_ticks = BLOCK_TICKS  # a block's length (ticks)
        self._first_block_ticks = BLOCK_TICKS  # the first block's
        self.blocks = 0  # blocks run ahead so far
        self._now = 0  # the substep the rig has reached (the drivetrain runs ahead)
        self._checkpoint: tuple[Any, ...] = ()
        self._calls: list[_Call] = []  # the rig's calls since the block's start
        self._silent = range(0)  # ticks a halt left without their predicted commands (``hold``)
        self.holds = 0  # blocks run again for a halt (``hold``)
        self.fell_back = False  # the forecast missed once: a plain Vehicle since

    def plan(self, forecast: Forecast, tick_s: float, start_s: float = 0.0, *,
             block_ticks: int = BLOCK_TICKS, first_block_ticks: int | None = None) -> None:
        """Run ahead from now on with ``forecast``; ticks every ``tick_s`` from ``start_s``, in
        blocks of ``block_ticks`` ticks, the first of ``first_block_ticks`` (None: the same).
        A block costs ~3.5-4 us of CPU a tick: shorter blocks, smaller bursts (real time)."""
        first = block_ticks if first_block_ticks is None else first_block_ticks
        if min(block_ticks, first) < 1:
            raise ValueError(f"a block runs at least one tick, got {min(block_ticks, first)}")
        self._forecast, self._tick_s, self._start_s = forecast, tick_s, start_s
        self._block_ticks, self._first_block_ticks = block_ticks, first

    def start(self) -> bool:
        """Run the first block now, from the tick the vehicle stands at (``start_s`` when it has
        not moved), instead of at the rig's first call: a real-time loop does it before its
        clock starts. False (a plain ``Vehicle`` from now) when it cannot (no forecast, off the
        tick grid, already running)."""
        if self._block is not None or self.fell_back or self._forecast is None:
            return False
        return self._start_first(self.drivetrain.substep / self.substep_hz)

    def replan(self, t_s: float, first_block_ticks: int) -> bool:
        """After a fall back (e.g. a real-time loop skipped ticks, so predicted commands never
        came): run ahead again from the rig's next tick, at ``t_s``, before any of its calls,
        the first block ``first_block_ticks`` long. The plain vehicle advances to ``t_s`` and
        syncs its truth first (as its own calls would: not a bit changes). False when it cannot
        (it did not fall back, no forecast, off the tick grid: a plain ``Vehicle`` still)."""
        if not self.fell_back or self._forecast is None:
            return False
        Vehicle.advance_to(self, t_s)
        self._sync_truth()
        self.fell_back = False
        self._first_block_ticks = first_block_ticks
        return self._start_first(t_s)

    def hold(self, ticks: range) -> bool:
        """A halt: the rig's ticks ``ticks``, after its latest call, bring their samples but
        none of their predicted commands (``sim.fleet``: a halted loop sends the gap's encoder
        samples alone), so the drive keeps its latest command through them. The forecast is
        silent at those ticks from now on, and when the current block predicted a command
        among them it is run again from the latest call to its own end (the rig's calls since
        its start replayed, as a fall back does): the drive stays planned, the next blocks
        start on the same ticks, and every count and pose is the plain vehicle's, call for
        call. False when the vehicle does not run ahead (no forecast, it fell back, no block
        yet: a first block reads the silence too) or a command the block predicted by its
        latest call never came (it falls back now, as its next call would)."""
        if self.fell_back or self._forecast is None or not ticks:
            return False
        self._silent = ticks
        block = self._block
        if block is None:
            return False
        first = self._next_tick - len(block.substeps)  # the block's first tick
        served = first + block.index[self._now] if self._calls else first - 1  # its latest
        pending = block.commands[block.next_command :]
        if ticks.start <= served or (pending and self._calls and pending[0][0] <= self._now):
            self._fall_back()
            return False
        if not _withheld(pending, block.substeps, ticks.start - first, ticks.stop - first):
            return True  # no predicted command among them: the block holds as it is
        end = self._next_tick
        self._rewind()
        self._next_tick = served + 1
        self._start_block(end - self._next_tick)
        self.holds += 1
        return True

    # --- the rig's calls ----------------------------------------------------------------------

    @property
    def t_s(self) -> float:
        """Current simulated time, s (the rig's, not the block's end)."""
        return (self._now if self._block is not None else self.drivetrain.substep) / self.substep_hz

    def advance_to(self, t_s: float) -> None:
        """``Vehicle.advance_to``, served from the block while the forecast holds."""
        served = self._served(t_s)
        if served is None:
            super().advance_to(t_s)
            return
        block, n = served
        nxt = block.next_command
        if n not in block.index or (nxt < len(block.commands) and block.commands[nxt][0] < n):
            self._fall_back()  # off the tick grid, or past a predicted command that never came
            super().advance_to(t_s)
            return
        self._now = n
        self._calls.append(t_s)

    def command(self, left_mps: float, right_mps: float, t_s: float) -> None:
        """``Vehicle.command``, checked against the forecast while it holds."""
        served = self._served(t_s)
        if served is None:
            super().command(left_mps, right_mps, t_s)
            return
        block, n = served
        nxt = block.next_command
        if nxt >= len(block.commands) or block.commands[nxt] != (n, left_mps, right_mps):
            self._fall_back()
            super().command(left_mps, right_mps, t_s)
            return
        block.next_command = nxt + 1
        self._now = n
        self._calls.append((left_mps, right_mps, t_s))

    def encoder_counts(self) -> tuple[int, int]:
        """Raw encoder counters now (the block's, recorded at this tick)."""
        block = self._block
        if block is None:
            return super().encoder_counts()
        return block.counts[block.index[self._now]]

    def truth(self) -> TruthPose:
        """The true pose now (the block's folds at this substep)."""
        if self._block is None:
            return super().truth()
        return self.truth_at(self._now)

    # --- the planned ticks' calls (sim.simplan: the block and the tick's substep known) ----------

    def served_command(self, n: int, left_mps: float, right_mps: float, t_s: float) -> None:
        """``command(left_mps, right_mps, t_s)`` from a plan of the current block: ``t_s`` is a
        tick of it and ``n`` its substep (``block_ahead``'s), so ``_served`` has nothing to find;
        the same checks against the forecast and the same record, else ``command`` itself."""
        block = self._block
        assert block is not None
        nxt = block.next_command
        commands = block.commands
        if n < self._now or nxt >= len(commands) or commands[nxt] != (n, left_mps, right_mps):
            self.command(left_mps, right_mps, t_s)
            return
        block.next_command = nxt + 1
        self._now = n
        self._calls.append((left_mps, right_mps, t_s))

    def served_advance(self, n: int, t_s: float) -> None:
        """``advance_to(t_s)`` from a plan of the current block (as ``served_command``)."""
        block = self._block
        assert block is not None
        nxt = block.next_command
        commands = block.commands
        if n < self._now or (nxt < len(commands) and commands[nxt][0] < n):
            self.advance_to(t_s)
            return
        self._now = n
        self._calls.append(t_s)

    # --- what a planner of the sim's frames reads (sim.simplan) ---------------------------------

    def block_ahead(
        self, k: int, t_s: float
    ) -> tuple[object, list[tuple[int, int]], list[int]] | None:
        """The block that serves tick ``k`` at ``t_s`` (started as the rig's first call at
        ``t_s`` would start it), the encoder counts it recorded at tick ``k`` and each tick
        after it to its end, and those ticks' substeps; None: the plain vehicle serves (no
        forecast, it fell back, or ``t_s`` is not tick ``k``'s time). The block is a token:
        ``serves(token)`` tells it still holds."""
        if t_s != self._start_s + k * self._tick_s:
            return None
        served = self._served(t_s)
        if served is None or served[1] not in served[0].index:
            return None
        block, n = served
        at = block.index[n]
        return block, block.counts[at:], block.substeps[at:]

    def serves(self, token: object) -> bool:
        """True while the block ``token`` (``block_ahead``) serves the rig's calls."""
        return self._block is token

    def tick_times(self, k: int, ticks: int) -> list[float]:
        """The times (s) of ticks ``k .. k + ticks - 1`` (``start_s + k * tick_s``: the same
        IEEE operations, in numpy)."""
        return (self._start_s + np.arange(k, k + ticks) * self._tick_s).tolist()  # type: ignore[no-any-return]

    def truths_at(self, times: list[float]) -> tuple[list[float], list[float], list[float]]:
        """The current block's true x, y (m) and heading (rad, wrapped) at each of ``times`` (on
        the tick grid: what ``truth`` gives after ``advance_to`` then), read at once."""
        block = self._block
        assert block is not None
        at = np.array([self._grid_substep(t_s) for t_s in times], dtype=np.int64) - block.truth_s0
        folds = block.folds
        headings = [wrap_angle(h) for h in block.heading[at].tolist()]
        return folds[0, at].tolist(), folds[1, at].tolist(), headings

    def truth_at(self, n: int) -> TruthPose:
        """The current block's true pose at substep ``n`` (what ``truth`` gives then)."""
        block = self._block
        assert block is not None
        j = n - block.truth_s0
        folds = block.folds
        return TruthPose(
            t_s=n / self.substep_hz,
            x_m=folds.item(0, j),
            y_m=folds.item(1, j),
            heading_rad=wrap_angle(block.heading.item(j)),
            distance_m=folds.item(2, j),
        )

    def truth_trace(self) -> TruthTrace:
        """``Vehicle.truth_trace`` (after a fall back: the block ran past now)."""
        self._fall_back()
        return super().truth_trace()

    def wheel_speeds_mps(self) -> tuple[float, float]:
        """``Vehicle.wheel_speeds_mps`` (after a fall back: the block ran past now)."""
        self._fall_back()
        return super().wheel_speeds_mps()

    # --- the blocks ---------------------------------------------------------------------------

    def _served(self, t_s: float) -> tuple[_Block, int] | None:
        """The block that serves a call at ``t_s`` (the next one started when ``t_s`` is past
        this one's end and every predicted command came) and the substep of ``t_s``; None: the
        plain vehicle does."""
        block = self._block
        if block is None:
            if self.fell_back or self._forecast is None or not self._start_first(t_s):
                return None
            block = self._block
            assert block is not None
        n = self._grid_substep(t_s)
        if n < self._now:  # Vehicle._substep_of against the rig's time, not the block's end
            raise VehicleError(f"time runs backwards: {t_s} s is before {self.t_s} s")
        if n > block.end:
            if block.next_command < len(block.commands):
                self._fall_back()
                return None
            self._start_block(self._block_ticks)
            block = self._block
            assert block is not None
        return block, n

    def _grid_substep(self, t_s: float) -> int:
        """The substep of ``t_s`` (``Vehicle._substep_of``'s grid, without its order check)."""
        try:
            return math.floor(t_s * self.substep_hz + _TIME_EPS)
        except (ValueError, OverflowError):  # NaN, inf
            raise VehicleError(f"time must be finite, got {t_s}") from None

    def _start_first(self, t_s: float) -> bool:
        """Start the first block at the tick of ``t_s``, when the vehicle stands exactly there
        with nothing pending (else the plain vehicle carries on)."""
        tick = round((t_s - self._start_s) / self._tick_s)
        at = self._grid_substep(self._start_s + tick * self._tick_s)
        drivetrain = self.drivetrain
        if tick < 0 or at != drivetrain.substep or drivetrain.pending_substeps:
            self.fell_back = True
            return False
        self._next_tick = tick
        self._now = at
        self._start_block(self._first_block_ticks)
        return True

    def _start_block(self, ticks: int) -> None:
        """Run the next ``ticks`` ticks with the forecast's commands, then their truth."""
        assert self._forecast is not None
        self._checkpoint = self._snapshot()
        self._calls = []
        block = _Block()
        forecast, start_s, tick_s = self._forecast, self._start_s, self._tick_s
        drivetrain = self.drivetrain
        advance, hz = drivetrain.advance, self.substep_hz
        floor = math.floor
        first = self._next_tick
        silent = self._silent
        if silent.start < first + ticks and first < silent.stop:  # a halt's gap in the block
            forecast = _silenced(forecast, silent)
        index, substeps = block.index, block.substeps
        angles: list[list[float]] = []  # the wheels' at each tick (a new list every segment)
        command, commands = drivetrain.command, block.commands
        for i, k in enumerate(range(first, first + ticks)):  # Vehicle.command and advance_to,
            t_s = start_s + k * tick_s  # unchecked
            n = floor(t_s * hz + _TIME_EPS)  # _grid_substep: t_s is finite here
            advance(n)
            speeds = forecast(k, t_s)
            if speeds is not None:
                command(speeds[0], speeds[1])
                commands.append((n, speeds[0], speeds[1]))
            index[n] = i
            substeps.append(n)
            angles.append(drivetrain.angle)
        block.counts = drivetrain.encoder_counts_at(angles)  # encoder_counts() of each, at once
        block.end = drivetrain.substep
        block.truth_s0 = self._truth.substep
        ds = self.drivetrain.take_travel()
        if ds.shape[0]:
            block.folds, block.heading = self._truth.advance_folds(
                self.errors.apply_slip(ds, self._rng)
            )
        else:
            truth = self._truth
            block.folds = np.array([[truth.x_m], [truth.y_m], [truth.distance_m]])
            block.heading = np.array([truth.heading_unwrapped_rad])
        self._next_tick = first + ticks
        self._block = block
        self.blocks += 1

    def _snapshot(self) -> tuple[Any, ...]:
        """What the block changes: the drivetrain's state, the truth's, the noise generator's."""
        d, t = self.drivetrain, self._truth
        return (
            (d.substep, list(d.omega), list(d.angle), list(d.setpoint), d._timeout_at,
             list(d._segments), d._pending),
            (t.substep, t.x_m, t.y_m, t.heading_unwrapped_rad, t.distance_m, len(t._trace)),
            self._rng.bit_generator.state if self.errors.slip else None,  # (it draws no noise)
        )

    def _fall_back(self) -> None:
        """Back to the block's start, the rig's calls since replayed: a plain Vehicle from now."""
        if self._block is not None:
            self._rewind()
        self.fell_back = True

    def _rewind(self) -> None:
        """The state at the block's start restored, the rig's calls since replayed on the plain
        vehicle: it stands at the latest call, no block."""
        drive, truth, rng = self._checkpoint
        d, t = self.drivetrain, self._truth
        (d.substep, d.omega, d.angle, d.setpoint, d._timeout_at, d._segments, d._pending) = drive
        (t.substep, t.x_m, t.y_m, t.heading_unwrapped_rad, t.distance_m, trace_len) = truth
        del t._trace[trace_len:]
        if rng is not None:
            self._rng.bit_generator.state = rng
        self._block = None
        for call in self._calls:
            if isinstance(call, tuple):
                Vehicle.advance_to(self, call[2])
                d.command(call[0], call[1])
            else:
                Vehicle.advance_to(self, call)
        self._calls = []


def _withheld(commands: list[tuple[int, float, float]], substeps: list[int], lo: int, hi: int
              ) -> bool:
    """True when one of ``commands`` (substep, left, right) falls on a tick at index ``lo ..
    hi - 1`` of a block whose ticks are at ``substeps``."""
    hi = min(hi, len(substeps))
    if lo >= hi:
        return False
    first, last = substeps[lo], substeps[hi - 1]
    return any(first <= n <= last for n, _, _ in commands)


def _silenced(forecast: Forecast, ticks: range) -> Forecast:
    """``forecast`` with no command at ``ticks`` (a halt's: ``PlannedVehicle.hold``)."""

    def silenced(k: int, t_s: float) -> tuple[float, float] | None:
        return None if k in ticks else forecast(k, t_s)

    return silenced
