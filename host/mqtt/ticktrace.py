"""An opt-in per-tick trace of a real-time fleet worker: where a late tick's time went.

Bench-only, off unless the environment names a directory: ``ODOCAN_TICK_TRACE=DIR`` makes every
worker of ``run_fleet`` (``odocan fleet``, ``bench/fleet.py``) write ``DIR/ticks-<first
robot>.jsonl`` when its clock stops, one JSON object per tick run:

``k`` (the tick's number), ``late_ms`` (its start after its release), and for each part of the
loop thread's time the wall and the thread CPU (``time.thread_time``) in microseconds:
``between`` (from the end of the previous tick to this one's start: the event loop's other work,
the MQTT links, the bridge's frame slices, the sleep), ``step`` (``Fleet.step`` and its batch),
``batch`` (``on_batch``: the bridge's ``offer``), ``gc`` (``TickCollector``'s young collection
when one is due, as in the run untraced: the worker's collector is off; ``gc_n`` the objects it
freed); ``proc_cpu_us``, the whole process's CPU over the tick and the time before it (the
command reader's thread included); ``ran``, what the event loop ran meanwhile, counted:
publications by leaf (``pose``, ``status``, ``rates``...), the command reader's hand-overs to the
loop (``reader``) and the progress reports (``progress``); ``runq_wait_us``, the time the loop
thread waited, runnable, for a CPU another thread or process held (Linux's
``/proc/thread-self/schedstat``); ``slow``, the event loop's handles (callbacks, task steps)
since the previous tick that took more than ``SLOW_HANDLE_US`` of thread CPU or judged more than
``BIG_HANDLE_FRAMES`` frames, each ``[name, cpu us, wall us, frames judged]`` (the step that ran
the tick left out; a ``gc genN`` entry: a collection that ran anyway, its wall time): the work a
tick's wake-up waits behind, whatever the load (the loop cannot preempt a handle: on an idle
machine a tick released while a 6 ms handle runs starts up to 6 ms late).

``bench/fleet_ticks.py`` reads these files: the late ticks' anatomy against the median tick.
Nothing of this runs without the variable (one ``os.environ`` lookup per run).
"""

from __future__ import annotations

import asyncio
import gc
import json
import os
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

from odocan.host.outputs import replaced
from odocan.sim.realtime import DeadlineStats

ENV = "ODOCAN_TICK_TRACE"
SLOW_HANDLE_US = 1000.0  # a loop handle taking more thread CPU than this is listed (``slow``)
BIG_HANDLE_FRAMES = 100  # ... or judging more frames than this


def from_env(first_robot: str) -> TickTrace | None:
    """The trace asked for by ``ODOCAN_TICK_TRACE`` (None: not asked, nothing traced)."""
    folder = os.environ.get(ENV)
    if not folder:
        return None
    return TickTrace(Path(folder) / f"ticks-{first_robot}.jsonl")


class TickTrace:
    """The per-tick figures of one worker's loop thread (see the module docstring)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.rows: list[dict[str, Any]] = []
        self.ran: Counter[str] = Counter()
        self._end_wall = self._end_cpu = self._end_proc = 0.0
        self._start_wall = self._start_cpu = 0.0
        self._row: dict[str, Any] = {}
        self.slow: list[list[Any]] = []
        self.fed = 0  # frames the bridge judged so far (``count_fed``)
        self._gc_start = 0.0
        self._schedstat = _open_schedstat()
        self._waited_ns = self._run_wait_ns()

    def _run_wait_ns(self) -> int:
        """The loop thread's time runnable but not running so far (ns; 0: not on Linux)."""
        if self._schedstat is None:
            return 0
        return int(os.pread(self._schedstat, 128, 0).split()[1])

    def time_handles(self) -> None:
        """Every asyncio handle's run timed from now on (this process): those over
        ``SLOW_HANDLE_US`` of thread CPU noted for the next tick's row."""
        run = asyncio.events.Handle._run
        slow = self.slow

        def timed(handle: asyncio.events.Handle) -> None:
            wall0, cpu0, fed0, rows0 = time.perf_counter(), time.thread_time(), self.fed, len(
                self.rows)
            run(handle)
            cpu_us = (time.thread_time() - cpu0) * 1e6
            frames = self.fed - fed0
            if (cpu_us > SLOW_HANDLE_US or frames > BIG_HANDLE_FRAMES) and len(self.rows) == rows0:
                slow.append([_handle_name(handle), round(cpu_us),
                             round((time.perf_counter() - wall0) * 1e6), frames])
        asyncio.events.Handle._run = timed  # type: ignore[method-assign,assignment]
        gc.callbacks.append(self._on_gc)

    def count_fed(self, feed: Callable[[Any], None]) -> Callable[[Any], None]:
        """``feed`` (the bridge's judge of a list of frames), its frames counted in ``fed``."""
        def counted(batch: Any) -> None:
            self.fed += len(batch)
            feed(batch)
        return counted

    def _on_gc(self, phase: str, info: dict[str, Any]) -> None:
        """A collection ran (the worker's collector should be off): noted as a slow handle."""
        if phase == "start":
            self._gc_start = time.perf_counter()
        else:
            self.slow.append([f"gc gen{info.get('generation')}", 0,
                              round((time.perf_counter() - self._gc_start) * 1e6), 0])

    def stats(self, period_s: float, late_after_s: float) -> DeadlineStats:
        """The loop's deadline accounting, each tick's start noted here."""
        return _TracedStats(period_s, late_after_s, trace=self)

    def collector_hook(self, on_batch: Callable[[Any], None] | None,
                       collect: Callable[[], int]) -> Callable[[Any], None]:
        """The loop's ``on_batch``: ``on_batch`` then ``collect`` (the young collection), each
        timed, then the tick's row closed."""
        def after_tick(batch: Any) -> None:
            wall0, cpu0 = time.perf_counter(), time.thread_time()
            self._part("step", wall0 - self._start_wall, cpu0 - self._start_cpu)
            if on_batch is not None:
                on_batch(batch)
            wall1, cpu1 = time.perf_counter(), time.thread_time()
            self._part("batch", wall1 - wall0, cpu1 - cpu0)
            self._row["gc_n"] = collect()
            wall2, cpu2 = time.perf_counter(), time.thread_time()
            self._part("gc", wall2 - wall1, cpu2 - cpu1)
            self._end(wall2, cpu2)
        return after_tick

    def counting(self, what: Callable[[Any], str], call: Callable[..., Any]) -> Callable[..., Any]:
        """``call``, each call counted under ``what(first argument)``."""
        def counted(*args: Any, **kwargs: Any) -> Any:
            self.ran[what(args[0] if args else None)] += 1
            return call(*args, **kwargs)
        return counted

    def tick_started(self, k: int, lateness_s: float) -> None:
        """Tick ``k`` starts ``lateness_s`` after its release."""
        wall, cpu, proc = time.perf_counter(), time.thread_time(), time.process_time()
        self._row = {"k": k, "late_ms": round(lateness_s * 1e3, 3),
                     "proc_cpu_us": 0.0, "ran": dict(self.ran), "slow": list(self.slow)}
        self.ran.clear()
        self.slow.clear()
        waited_ns = self._run_wait_ns()
        self._row["runq_wait_us"] = round((waited_ns - self._waited_ns) / 1e3, 1)
        self._waited_ns = waited_ns
        if self._end_wall:
            self._part("between", wall - self._end_wall, cpu - self._end_cpu)
        self._start_wall, self._start_cpu = wall, cpu
        self._row["_proc0"] = self._end_proc or proc

    def _part(self, name: str, wall_s: float, cpu_s: float) -> None:
        self._row[f"{name}_wall_us"] = round(wall_s * 1e6, 1)
        self._row[f"{name}_cpu_us"] = round(cpu_s * 1e6, 1)

    def _end(self, wall: float, cpu: float) -> None:
        proc = time.process_time()
        self._row["proc_cpu_us"] = round((proc - self._row.pop("_proc0")) * 1e6, 1)
        self.rows.append(self._row)
        self._end_wall, self._end_cpu, self._end_proc = wall, cpu, proc

    def write(self) -> None:
        """The rows to ``path``, one JSON object a line (the folder made if needed), in full or
        not at all (``host.outputs.replaced``: written in place, a full disk or a signal part-way
        cut an older trace); a failed write is one ``OutputError`` naming the path."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with replaced(self.path, ENV) as target, target.open("w", encoding="utf-8") as out:
            for row in self.rows:
                out.write(json.dumps(row) + "\n")


class _TracedStats(DeadlineStats):
    """``DeadlineStats`` that tells its trace when each tick starts."""

    def __init__(self, period_s: float, late_after_s: float, *, trace: TickTrace) -> None:
        super().__init__(period_s, late_after_s)
        self.trace = trace

    def record(self, lateness_s: float) -> None:
        self.trace.tick_started(self.ticks, lateness_s)
        super().record(lateness_s)


def _open_schedstat() -> int | None:
    """This thread's ``/proc/thread-self/schedstat`` open (None where there is none): its
    second field is the time it waited on a run queue, runnable (another process had the
    CPU)."""
    try:
        return os.open("/proc/thread-self/schedstat", os.O_RDONLY)
    except OSError:
        return None


def _handle_name(handle: asyncio.events.Handle) -> str:
    """A handle's callback by name: a task step by its coroutine's qualified name."""
    callback = getattr(handle, "_callback", None)
    task = getattr(callback, "__self__", None)
    if isinstance(task, asyncio.Task):
        coro = task.get_coro()
        return f"task {getattr(coro, '__qualname__', coro)}"
    return str(getattr(callback, "__qualname__", callback))
