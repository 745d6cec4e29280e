"""A fleet's archive: many CAN logs analysed in parallel, locally or on a Dask cluster.

``find_logs`` expands the paths a person gives (files, and directories searched recursively for
``.log``, ``.asc`` and ``.blf``); ``analyze_logs`` runs ``analyze_one`` on every log in a pool of
processes (``jobs``) or, given a scheduler address, on a Dask distributed cluster. One log's
failure (unreadable, not odocan's frames) is that log's result, never the batch's end: every log
gets a ``LogResult`` saying frames, verdict and largest errors, or why it could not be analysed.

Workers receive plain values (paths, names, numbers) and return plain values (the JSON report as
a dict), so the same function runs in a ``ProcessPoolExecutor`` and on a remote Dask worker.
"""

from __future__ import annotations

import gc
import os
import socket
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from odocan.sim.exceptions import OdocanError

if TYPE_CHECKING:
    from odocan.host.io.logs import FrameArrays
    from odocan.host.judge.analysis import Tolerance
    from odocan.host.judge.diagnosis import Judged
    from odocan.host.judge.profilepage import RunningProfile
    from odocan.sim.robot import RobotProfile

LOG_SUFFIXES = (".log", ".asc", ".blf")


class DaskUnavailableError(OdocanError):
    """The ``--dask`` scheduler cannot be reached (or dask is not installed)."""


@dataclass(frozen=True)
class Job:
    """What every log is analysed with: robot profile name (None: each log's own, from its
    PROFILE page, ``host.cli.robotchoice``), integrator (None: the one the log's
    ODOM_STATUS reports), position tolerance in metres, heading tolerance in radians, and the
    DBC path (None: odocan's own), and whether to stream each log (``stream_analysis.streams``:
    auto, always, never)."""

    robot: str | None
    integrator: str | None
    tolerance_position_m: float
    tolerance_heading_rad: float
    dbc: str | None = None
    stream: str = "auto"


@dataclass(frozen=True)
class LogResult:
    """One log's outcome: ``report`` (the JSON report, as ``odocan analyze LOG --report`` writes
    it) when analysed, else ``error`` (one line: why it could not be read or analysed)."""

    path: str
    report: dict[str, Any] | None = None
    error: str | None = None
    frames: int | None = None  # frames in the log, whatever their ID (None: not read)
    refused: str | None = None  # why ``--stream always`` read it whole (NotStreamable), if so
    passed: bool = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "passed", bool(self.report and self.report.get("passed")))


def find_logs(paths: Sequence[Path]) -> tuple[list[Path], list[str]]:
    """The logs named by ``paths`` in order (a directory contributes its ``LOG_SUFFIXES`` files,
    recursively, sorted; a file is taken whatever its suffix, so a bad one gets named later),
    and one line per path that gives no log at all (missing, or a directory without logs)."""
    logs: list[Path] = []
    problems: list[str] = []
    for path in paths:
        if path.is_dir():
            found = sorted(
                p for p in path.rglob("*") if p.suffix.lower() in LOG_SUFFIXES and p.is_file()
            )
            if not found:
                problems.append(f"{path}: no .log, .asc or .blf file in this directory")
            logs.extend(found)
        elif path.exists():
            logs.append(path)
        else:
            problems.append(f"{path}: no such log file or directory")
    unique = list(dict.fromkeys(p.resolve() for p in logs))
    return [Path(os.path.relpath(p)) if _under_cwd(p) else p for p in unique], problems


def _under_cwd(path: Path) -> bool:
    return path.is_relative_to(Path.cwd())


def analyze_one(path: str, job: Job) -> LogResult:
    """Read and analyse one log (runs in a worker process); never raises for a bad log. As
    ``analyze LOG``: the firmware's PROFILE page gives the judges its speed bound and names a
    wrong ``--robot`` (``host.judge.profilepage``), then a failed verdict's pose fit does."""
    from odocan.host.cli.inputs import explained, require_frames
    from odocan.host.cli.robotchoice import choose_robot
    from odocan.host.cli.subparsers.analyze import load_judges_dbc, log_inputs
    from odocan.host.io.logs import read_log
    from odocan.host.judge import verdictfacts
    from odocan.host.judge.analysis import Tolerance, analyze
    from odocan.host.judge.configs import ConfigPages, later_mismatches, running_before_configs
    from odocan.host.judge.diagnosis import judged_before
    from odocan.host.judge.profilepage import head_profile, with_bus_speed
    from odocan.host.judge.samples import AnalysisError
    from odocan.host.judge.stream_analysis import FrameCount, NotStreamable, analyze_file, streams

    log = Path(path)
    try:
        choice = choose_robot(job.robot, log, from_log=job.dbc is None)
        profile = choice.profile
        tolerance = Tolerance(job.tolerance_position_m, job.tolerance_heading_rad)
        db = load_judges_dbc(Path(job.dbc)) if job.dbc is not None else None
        streamed: dict[str, Any] | None = None
        refused: str | None = None
        count = FrameCount()
        running = None  # the log's PROFILE page (odocan's DBC only)
        later: list[str] = []  # its pages after an applied config, against the config's robot
        frames: FrameArrays | None = None  # the whole log, when read
        judged: Judged | None = None  # its verdict, for the pose fit (diagnosis)
        if streams(log, job.stream):  # in bounded memory (host.judge.stream_analysis)
            running = head_profile(log) if db is None else None
            pages = ConfigPages(profile) if db is None else None  # an applied config's
            try:
                streamed = analyze_file(log, with_bus_speed(profile, running), job.integrator,
                                        tolerance=tolerance, db=db, warn=lambda message: None,
                                        count=count, whole_on_config=db is None,
                                        config_pages=pages, whole_on_ahead=False)
                if pages is not None:  # the pages read from the stream's spill
                    running = pages.running(running)
                    later = pages.mismatches(streamed["integrator"])
            except AnalysisError:  # the whole log's path says why, in the log's terms
                streamed = None
            except NotStreamable as refusal:  # said under --stream always (analyze.py)
                refused = str(refusal) if job.stream == "always" else None
        if streamed is not None:
            report, n_frames = streamed, count.frames
        else:  # the whole log: the same report
            frames = read_log(log, warn=lambda message: None)
            n_frames = len(frames)
            if db is not None:
                analysis = analyze(frames, profile, job.integrator, tolerance=tolerance, db=db)
            else:
                require_frames(frames, path)
                running = running_before_configs(frames, profile.counter_bits)  # its bound
                judged_as = with_bus_speed(profile, running)
                with explained(lambda: frames, path):
                    analysis = analyze(frames, judged_as, job.integrator, tolerance=tolerance)
                if not analysis.passed:  # the pose fit need not judge judged_as again
                    judged = judged_before(frames, judged_as, job.integrator, tolerance,
                                           analysis)
                later = later_mismatches(frames, profile, analysis.report["integrator"])
            report = analysis.report
        report["inputs"] = choice.recorded(log_inputs(
            log, profile, report["integrator"], None if job.dbc is None else Path(job.dbc)))
        verdictfacts.mark(report)  # a check on 0 samples, a stuck E2E COUNTER: no PASS
        _diagnose(log, report, profile, running, tolerance, db is None, later, choice.given_as,
                  (frames, judged))
    except (OdocanError, OSError) as exc:
        return LogResult(path, error=_one_line(exc))
    except Exception as exc:  # a log no check foresaw: this log's error, the batch goes on
        return LogResult(path, error=f"cannot analyse: {type(exc).__name__}: {_one_line(exc)}")
    return LogResult(path, report=_plain(report), frames=n_frames, refused=refused)


def _diagnose(log: Path, report: dict[str, Any], profile: RobotProfile,
              running: RunningProfile | None, tolerance: Tolerance, own_dbc: bool,
              later: list[str], given_as: str,
              read: tuple[FrameArrays | None, Judged | None] = (None, None)) -> None:
    """``report["diagnosis"]`` as ``analyze LOG`` makes it: the PROFILE page's line naming a
    wrong ``--robot``, ``later`` (the pages after an applied config, host.judge.configs),
    then, for a failed verdict on odocan's DBC, the pose fit's (``given_as``: how they name
    the robot, ``host.cli.robotchoice``; ``read``: the whole log when it was read, not read
    again, and its verdict, ``diagnosis.judged_before``)."""
    from odocan.host.io.logs import read_log
    from odocan.host.judge.profilepage import profile_mismatch, with_bus_speed

    said = profile_mismatch(running, profile, report["integrator"], given_as)
    hints = ([] if said is None else [said]) + later
    whole, judged = read
    if own_dbc and report["integrator_source"] == "argument":  # not the firmware's: a FAIL
        from odocan.host.judge.diagnosis import logged_integrator, mark_integrator

        whole = whole if whole is not None else read_log(log, warn=lambda message: None)
        mark_integrator(report, logged_integrator(whole))  # its line: mismatches' hint
    if not report["passed"] and own_dbc:  # a wrong --robot must not read as a firmware fault
        from odocan.host.judge.diagnosis import mismatches

        whole = whole if whole is not None else read_log(log, warn=lambda message: None)
        hints += mismatches(whole, with_bus_speed(profile, running), report["integrator"],
                            report["integrator_source"], tolerance, given_as, judged)  # wrong: said
    if hints:
        report["diagnosis"] = hints


def _plain(value: Any) -> Any:
    """``value`` with numpy scalars and arrays as Python numbers and lists (pickles anywhere)."""
    import numpy as np

    if isinstance(value, dict):
        return {key: _plain(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(item) for item in value]
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return value


def _one_line(exc: BaseException) -> str:
    return " ".join((str(exc) or type(exc).__name__).split())


def analyze_logs(
    logs: Sequence[Path],
    job: Job,
    *,
    jobs: int,
    on_done: Callable[[LogResult], None] = lambda result: None,
) -> list[LogResult]:
    """Every log analysed in ``jobs`` worker processes (1: in this process); results in the
    order of ``logs``; ``on_done`` is called as each one finishes."""
    paths = [str(p) for p in logs]
    if jobs <= 1 or len(paths) == 1:
        results = []
        for path in paths:
            results.append(analyze_one(path, job))
            on_done(results[-1])
        return results
    from concurrent.futures import ProcessPoolExecutor, as_completed

    by_path: dict[str, LogResult] = {}
    with ProcessPoolExecutor(max_workers=min(jobs, len(paths))) as pool:
        futures = {pool.submit(analyze_one, path, job): path for path in paths}
        try:
            for future in as_completed(futures):
                by_path[futures[future]] = result = _outcome(futures[future], future.result)
                on_done(result)
        except BaseException:  # Ctrl-C, SIGTERM: the pool's exit would run every queued log
            _stop_pool(pool)
            raise
    return [by_path[path] for path in paths]


def _stop_pool(pool: Any) -> None:
    """Cancel the logs still queued and end the workers' logs under way (a 1 GB log takes
    half a minute): the pool's exit then only joins its processes. They only read logs and
    return reports: nothing of theirs is left half written."""
    # CPython's workers, by their private name (no public way in 3.11), taken before
    # shutdown() forgets them; SIGKILL, for a forked worker inherits the CLI's SIGTERM handler
    # and would go on to its next log
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.kill()


def _outcome(path: str, result: Callable[[], LogResult]) -> LogResult:
    """``result()``, or the log's error when its worker died (killed, out of memory)."""
    try:
        return result()
    except Exception as exc:  # BrokenProcessPool, dask's KilledWorker, a lost connection ...
        return LogResult(path, error=f"worker lost: {type(exc).__name__}: {_one_line(exc)}")


def analyze_logs_dask(
    logs: Sequence[Path],
    job: Job,
    *,
    address: str,
    timeout_s: float,
    on_done: Callable[[LogResult], None] = lambda result: None,
) -> list[LogResult]:
    """Every log analysed on the Dask distributed cluster whose scheduler is at ``address``
    (``tcp://host:port``); ``DaskUnavailableError`` (one line) when it cannot be reached within
    ``timeout_s`` seconds. The workers must be able to import odocan and read the log paths
    (given absolute)."""
    paths = [str(Path(p).resolve()) for p in logs]
    shown = {str(Path(p).resolve()): str(p) for p in logs}
    client = _connect(address, timeout_s)
    results: list[LogResult] = []
    with client:
        futures = client.map(analyze_one, paths, job=job, pure=False)
        for path, future in zip(paths, futures, strict=True):
            done = _outcome(path, future.result)
            results.append(LogResult(shown[path], done.report, done.error, done.frames,
                                     done.refused))
            on_done(results[-1])
    return results


def _connect(address: str, timeout_s: float) -> Any:
    """A ``distributed.Client`` of the scheduler at ``address``, or ``DaskUnavailableError``
    (one line) within about ``timeout_s`` seconds: a bad address, nobody listening, or a peer
    that does not speak Dask's protocol."""
    try:
        from distributed import Client
        from distributed.comm.addressing import get_address_host_port, parse_address
    except ImportError as exc:
        raise DaskUnavailableError(f"--dask needs dask.distributed: {exc}") from None
    where = f"--dask {address}"
    try:
        scheme, _ = parse_address(address)
        host, port = get_address_host_port(address) if scheme in ("tcp", "tls") else ("", 0)
    except ValueError as exc:
        raise DaskUnavailableError(f"{where}: not a scheduler address ({_one_line(exc)})") from None
    if host:
        try:
            socket.create_connection((host, port), timeout=timeout_s).close()
        except OSError as exc:
            raise DaskUnavailableError(
                f"{where}: cannot connect within {timeout_s:g} s ({_one_line(exc)})"
            ) from None
    hook = sys.unraisablehook  # a Client that failed half-made complains as it is collected
    sys.unraisablehook = lambda unraisable: None
    try:
        return Client(address, timeout=timeout_s, set_as_default=False)  # type: ignore[no-untyped-call]
    except Exception as exc:  # a timeout, or a peer that is no Dask scheduler (any error)
        message = f"{where}: no Dask scheduler answered within {timeout_s:g} s ({_one_line(exc)})"
    finally:
        gc.collect()
        sys.unraisablehook = hook
    raise DaskUnavailableError(message)


def report_names(logs: Sequence[Path]) -> dict[Path, str]:
    """A distinct JSON file name per log: its path below the logs' common folder with ``/`` as
    ``__`` and ``.json`` appended (``a/drive.log`` -> ``a__drive.log.json``)."""
    resolved = [p.resolve() for p in logs]
    if not resolved:
        return {}
    root = Path(os.path.commonpath([p.parent for p in resolved]))
    return {
        log: "__".join(path.relative_to(root).parts) + ".json"
        for log, path in zip(logs, resolved, strict=True)
    }
