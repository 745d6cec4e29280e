"""A fleet across cores and machines: shards, worker processes, the embedded broker's process.

``Shard.parse("K/N")`` is this machine's part of a fleet run by N machines against one broker:
robots ``split(total, N)[K - 1]``, named and seeded by their fleet-wide index
(``sim.fleet.FleetConfig.first``), so ids never clash. Within a shard, ``run_sharded`` spreads the
robots over ``workers`` processes (multiprocessing *spawn*: no state forked from the parent), each
running its slice's real-time loop and bridge with its own MQTT connections
(``host.mqtt.fleetrun.run_fleet``); one worker runs in this process. The parent aggregates the
workers' reports: ``per_robot`` merged, ``workers`` listing each one's deadline figures, and
``deadline_miss_ratio`` the WORST worker's (a robot's ticks are its worker's ticks: an average
would hide a late worker). SIGINT/SIGTERM to the parent is passed on: every worker stops and
reports, as at the end of ``--duration``.

``BrokerProcess`` runs the embedded amqtt broker in a process of its own (never in a worker, so
the broker's CPU does not delay any robot's ticks) on a fixed or free 127.0.0.1 port; a port in
use is a one-line ``ConfigurationError``. Workers and the broker stop by themselves when the
parent is killed -9 (they watch their parent process id).
"""

from __future__ import annotations

import asyncio
import multiprocessing as mp
import os
import queue
import signal
import socket
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from multiprocessing.connection import Connection
from typing import Any

from odocan.host.mqtt.broker import (
    LOOPBACK,
    BrokerError,
    BrokerURL,
    EmbeddedBroker,
    free_loopback_port,
)
from odocan.host.mqtt.fleetrun import FleetRun, StartHook, run_fleet
from odocan.host.mqtt.options import configure_logging
from odocan.sim.exceptions import ConfigurationError, OdocanError, Terminated

MAX_SHARDS = 1000
# spawn + importing amqtt on a loaded machine: 20 s was cut short under load (a CI-like 2-core
# machine, nice 19, load ~10: "did not start within 20 s" while it was still importing)
BROKER_START_S = 60.0
BROKER_POLL_S = 0.1  # how often the start looks whether the broker process still lives
BROKER_JOIN_S = 5.0  # a broker process that closed its pipe: its exit code within this
WORKER_RESULT_S = 60.0  # after the duration: the goodbye of every link, then the report
ORPHAN_CHECK_S = 1.0  # a worker or broker whose parent died stops within this
Progress = Callable[[int, int], None]  # (ticks, late ticks) summed over the workers so far


@dataclass(frozen=True)
class Shard:
    """Part ``index`` (1-based) of ``count`` of a fleet (``--shard K/N``)."""

    index: int = 1
    count: int = 1

    @classmethod
    def parse(cls, text: str) -> Shard:
        """``K/N`` with 1 <= K <= N <= ``MAX_SHARDS``; ``ValueError`` saying what is wrong."""
        k, sep, n = text.partition("/")
        if not sep or not k.strip().isdigit() or not n.strip().isdigit():
            raise ValueError(f"expected K/N (part K of N, e.g. 1/2), got {text!r}")
        shard = cls(int(k), int(n))
        if not 1 <= shard.count <= MAX_SHARDS:
            raise ValueError(f"N must be in [1, {MAX_SHARDS}], got {text}")
        if not 1 <= shard.index <= shard.count:
            raise ValueError(f"K must be in [1, {shard.count}], got {text}")
        return shard

    def robots(self, total: int) -> tuple[int, int]:
        """(first fleet-wide index, how many) of this shard's robots among ``total``."""
        first, count = split(total, self.count)[self.index - 1]
        if count == 0:
            raise ConfigurationError(
                f"--shard {self.index}/{self.count}: no robot left for it of {total} (-n)")
        return first, count


def split(total: int, parts: int) -> list[tuple[int, int]]:
    """``total`` items in ``parts`` contiguous slices as (first, count), sizes differing by <= 1."""
    edges = [total * p // parts for p in range(parts + 1)]
    return [(edges[p], edges[p + 1] - edges[p]) for p in range(parts)]


def check_port_free(port: int) -> None:
    """``ConfigurationError`` when 127.0.0.1:``port`` cannot be listened on (in use). With
    SO_REUSEADDR, as the broker's own listener (asyncio's) binds: connections of a run that just
    ended, in TIME_WAIT for a minute, do not keep a port from the next run; a listener does."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((LOOPBACK, port))
        except OSError as exc:
            raise ConfigurationError(
                f"--port {port}: {LOOPBACK}:{port} cannot be used ({exc.strerror})") from None


class BrokerProcess:
    """The embedded amqtt broker in its own process (see the module docstring)."""

    def __init__(self, *, port: int | None = None) -> None:
        self.port = port
        self._proc: Any = None

    def start(self, timeout_s: float = BROKER_START_S) -> BrokerURL:
        """Start it and wait until it listens; its URL (MQTT 3.1.1: amqtt)."""
        port = self.port if self.port is not None else free_loopback_port()
        check_port_free(port)
        ctx = mp.get_context("spawn")
        ours, theirs = ctx.Pipe(duplex=False)
        self._proc = ctx.Process(target=_serve_broker, args=(port, theirs),
                                 name="odocan-broker", daemon=True)
        self._proc.start()
        theirs.close()
        answer = self._answer(ours, timeout_s)
        if answer != "ok":
            self.stop()
            raise BrokerError(f"the embedded broker on {LOOPBACK}:{port}: {answer}")
        self.port = port
        return BrokerURL(host=LOOPBACK, port=port, v5=False)

    def _answer(self, ours: Connection, timeout_s: float) -> str:
        """The broker's first word on ``ours`` ("ok" or why not): waited for while its process
        lives, ``timeout_s`` at most; ``BrokerError`` (the broker stopped) when it did not say
        it in time, or its process ended first (before: an ``EOFError`` traceback)."""
        deadline = time.monotonic() + timeout_s
        while not ours.poll(BROKER_POLL_S):
            if not self._proc.is_alive():
                raise self._ended()
            if time.monotonic() > deadline:
                self.stop()
                raise BrokerError(f"the embedded broker did not start within {timeout_s:g} s")
        try:
            return str(ours.recv())
        except EOFError:  # its end closed the pipe
            raise self._ended() from None

    def _ended(self) -> BrokerError:
        """The error of a broker process that ended before it listened (it is reaped)."""
        proc = self._proc
        proc.join(BROKER_JOIN_S)
        self.stop()
        return BrokerError(f"the embedded broker exited (code {proc.exitcode}) before it "
                           "listened")

    @property
    def pid(self) -> int | None:
        """The broker process's id while it runs."""
        return None if self._proc is None else int(self._proc.pid)

    def stop(self) -> None:
        """Stop it (SIGTERM, then SIGKILL after 5 s)."""
        proc, self._proc = self._proc, None
        if proc is None:
            return
        proc.terminate()
        proc.join(5.0)
        if proc.is_alive():
            proc.kill()
            proc.join()


def _serve_broker(port: int, ready: Connection) -> None:
    """The broker process: listen, say ``ok`` (or why not) on ``ready``, serve until killed."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C stops the fleet; the parent stops us

    async def serve() -> None:
        try:
            broker = EmbeddedBroker(port=port)
            await broker.start()
        except Exception as exc:  # the reason goes to the parent, as one line
            ready.send(str(exc) or type(exc).__name__)
            return
        ready.send("ok")
        while os.getppid() == parent:  # an orphan (the parent killed -9) stops by itself
            await asyncio.sleep(ORPHAN_CHECK_S)

    parent = os.getppid()

    asyncio.run(serve())


@contextmanager
def embedded_broker(port: int | None) -> Iterator[BrokerURL]:
    """A ``BrokerProcess`` for the duration of the block."""
    broker = BrokerProcess(port=port)
    url = broker.start()
    try:
        yield url
    finally:
        broker.stop()


def run_sharded(
    run: FleetRun, workers: int, *, on_start: StartHook | None = None,
    on_progress: Progress | None = None, debug: bool = False, spawn: bool = False,
) -> dict[str, Any]:
    """Run ``run.fleet`` over ``workers`` processes (1: in this one, unless ``spawn``: a worker
    that imports its modules afresh, compiled by ``host.accel.for_children``); the aggregated
    report. Bridged without a broker: one ``BrokerProcess`` for all of them, for the run."""
    if not 1 <= workers <= run.fleet.robots:
        raise ConfigurationError(
            f"--workers {workers}: must be in [1, {run.fleet.robots}] (the robots to run)")
    if run.bridge and run.broker is None:
        with embedded_broker(None) as url:
            report = run_sharded(replace(run, broker=url), workers, on_start=on_start,
                                 on_progress=on_progress, debug=debug, spawn=spawn)
        return {**report, "embedded_broker": True}
    if workers == 1 and not spawn:
        return asyncio.run(run_fleet(
            run, on_start=on_start,
            on_progress=None if on_progress is None else
            lambda s: on_progress(s.ticks, s.late_ticks)))
    epoch_s = time.monotonic()  # the workers' clocks 1/workers of a period apart after it
    runs = [replace(run, fleet=run.fleet.shard(first, count), clock_phase=(epoch_s, w / workers))
            for w, (first, count) in enumerate(split(run.fleet.robots, workers))]
    return aggregate(_run_workers(runs, on_start, on_progress, debug))


def _run_workers(
    runs: list[FleetRun], on_start: StartHook | None, on_progress: Progress | None, debug: bool,
) -> list[dict[str, Any]]:
    """One spawned process per run; their reports in order (the first error of any raised)."""
    ctx = mp.get_context("spawn")
    events: Any = ctx.Queue()
    procs = [ctx.Process(target=_work, args=(w, r, events, debug), name=f"odocan-fleet-{w}")
             for w, r in enumerate(runs)]
    for proc in procs:
        proc.start()
    signals: list[int] = []  # the ones this process got: passed on to every worker

    def stop(signum: int, frame: object) -> None:
        signals.append(signum)
        _stop_all(procs)

    previous = {s: signal.signal(s, stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        return _collect(runs, procs, events, on_start, on_progress, signals)
    except BaseException:
        _stop_all(procs)
        raise
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        for proc in procs:
            proc.join(10.0)
            if proc.is_alive():
                proc.kill()
                proc.join()


def _stop_all(procs: list[Any]) -> None:
    """SIGTERM to every worker still running: each stops its clock and reports."""
    for proc in procs:
        if proc.is_alive():
            proc.terminate()


def _collect(
    runs: list[FleetRun], procs: list[Any], events: Any, on_start: StartHook | None,
    on_progress: Progress | None, signals: list[int],
) -> list[dict[str, Any]]:
    """Wait for every worker's report, passing on start and progress events (``signals``:
    those passed on to the workers so far)."""
    reports: dict[int, dict[str, Any]] = {}
    started: set[int] = set()
    progress: dict[int, tuple[int, int]] = {}
    deadline = time.monotonic() + max(r.duration_s for r in runs) + 2 * BROKER_START_S \
        + WORKER_RESULT_S
    while len(reports) < len(runs):
        try:
            worker, kind, value = events.get(timeout=0.2)
        except queue.Empty:
            _check_alive(procs, reports, deadline, signals)
            continue
        if kind == "error":
            raise (BrokerError if value[0] == "broker" else OdocanError)(value[1])
        if kind == "report":
            reports[worker] = value
        elif kind == "started":
            started.add(worker)
            if len(started) == len(runs) and on_start is not None:
                on_start(sum(r.fleet.robots for r in runs), runs[0].broker)
        elif kind == "progress" and on_progress is not None:
            progress[worker] = value
            on_progress(sum(t for t, _ in progress.values()),
                        sum(late for _, late in progress.values()))
    return [reports[w] for w in range(len(runs))]


def _check_alive(
    procs: list[Any], reports: dict[int, Any], deadline: float, signals: list[int]
) -> None:
    """``OdocanError`` when a worker ended without its report, or the reports are overdue; the
    interruption itself (``KeyboardInterrupt``, ``Terminated`` for SIGTERM) when the worker
    was stopped by the signal passed on from this process before it could report (a Ctrl-C
    or SIGTERM while the workers start: no fleet ran, and that is not a worker's fault)."""
    dead = [w for w, p in enumerate(procs) if w not in reports and not p.is_alive()]
    if dead and signals and procs[dead[0]].exitcode in (-signal.SIGTERM, -signal.SIGINT):
        raise Terminated if signals[0] == signal.SIGTERM else KeyboardInterrupt
    if dead:
        raise OdocanError(f"fleet worker {dead[0]} ended without a report "
                          f"(exit code {procs[dead[0]].exitcode})")
    if time.monotonic() > deadline:
        raise OdocanError("fleet workers did not report in time")


def _stop_when_orphaned() -> None:
    """A daemon thread: SIGTERM to this worker once its parent is gone (killed -9), so it stops
    like at the end of its duration instead of running on unseen."""
    parent = os.getppid()

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(ORPHAN_CHECK_S)
        os.kill(os.getpid(), signal.SIGTERM)

    threading.Thread(target=watch, name="odocan-orphan-watch", daemon=True).start()


def _work(worker: int, run: FleetRun, events: Any, debug: bool) -> None:
    """A worker process: run its slice, put ``(worker, kind, value)`` events, the report last."""
    configure_logging(debug)
    _stop_when_orphaned()
    try:
        report = asyncio.run(run_fleet(
            run, on_start=lambda robots, url: events.put((worker, "started", robots)),
            on_progress=lambda s: events.put((worker, "progress", (s.ticks, s.late_ticks)))))
    except BrokerError as exc:
        events.put((worker, "error", ("broker", str(exc))))
    except OdocanError as exc:
        events.put((worker, "error", ("odocan", str(exc))))
    except Exception as exc:  # a defect: still one line in the parent
        events.put((worker, "error", ("odocan", f"worker {worker}: {type(exc).__name__}: {exc}")))
    else:
        events.put((worker, "report", report))


_WORKER_FIELDS = ("robots", "first_robot", "deadline_miss_ratio", "ticks", "late_ticks",
                  "skipped_releases", "max_lateness_ms", "cpu_s")


def aggregate(reports: list[dict[str, Any]]) -> dict[str, Any]:
    """One fleet report of the workers' (see the module docstring)."""
    worst = max(reports, key=lambda r: r["deadline_miss_ratio"])
    bridge = None
    if all(r["bridge"] is not None for r in reports):
        totals: Counter[str] = Counter()
        for r in reports:
            totals.update({k: v for k, v in r["bridge"].items() if isinstance(v, int)})
        bridge = dict(totals)
    per_robot: dict[str, Any] = {}
    for r in reports:
        per_robot.update(r["per_robot"])
    return {
        **{k: v for k, v in reports[0].items() if k not in ("per_robot", "bridge")},
        "robots": sum(r["robots"] for r in reports),
        "duration_s": max(r["duration_s"] for r in reports),  # what ran: the longest worker
        "deadline_miss_ratio": worst["deadline_miss_ratio"],
        "ticks": sum(r["ticks"] for r in reports),
        "late_ticks": sum(r["late_ticks"] for r in reports),
        "skipped_releases": sum(r["skipped_releases"] for r in reports),
        "max_lateness_ms": max(r["max_lateness_ms"] for r in reports),
        "cpu_s": sum(r["cpu_s"] for r in reports),
        "workers": [{k: r[k] for k in _WORKER_FIELDS} for r in reports],
        "bridge": bridge,
        "per_robot": per_robot,
        "stopped": next((r["stopped"] for r in reports if r.get("stopped")), None),
    }
