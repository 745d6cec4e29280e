"""``odocan monitor``: a live terminal view of a CAN bus, or of a fleet over MQTT.

On any python-can bus (``-i/-c/-b``, or python-can's configuration) every frame is fed to
``host.judge.monitor.BusMonitor``: decoded signals per message with units, rate and period
jitter, E2E counts, the firmware's status, and the on-board pose against the float64 reference
(and SIM_TRUTH when present). The screen (``host.report.tui``, fits 80×24) redraws it a few times
a second until Ctrl-C or ``q`` (exit 0) or ``--duration``, with a decoded trace (``--filter``,
pause with space or ``p``); ``--log PATH`` records every frame heard, on a thread that reads the
bus before any judging (``host.io.busreader``: a slow judge or screen never costs the log a
frame). What this process itself lost (frames the kernel dropped on its socket, frames recorded
that the judge skipped) is said apart from what the bus lost (the E2E ``lost`` counts, which
include both): a ``lost here:`` line on stderr and on the screen, ``receive`` in the JSON.
With ``--json`` there is no screen: at the end (``--duration`` or Ctrl-C) the
model is printed as one JSON object, for scripts. A ``--duration`` watch that Ctrl-C or SIGTERM
ends early says so (``stopped`` in the JSON, a line on stderr) and exits 130/143, never 0.
A watch that saw the on-board pose wrong (``health.pose_wrongs``: every POSE WRONG episode
latched, ``host.judge.posewrongs``), even if it was right again by the end, says so on stderr
(``monitor: FAIL: the on-board pose was wrong in ...``) and exits 1 (or 130/143 when a signal
ended it early); else 0.

``--broker [URL]`` (alias ``--mqtt``, the name it had) shows the fleet instead: one row per
robot that ``odocan bridge``/``odocan fleet`` publish (``host.mqtt.fleetview.fleet_states``),
reconnecting when the broker goes away, redrawn on a timer (stale robots marked, the worst error
first).
"""

from __future__ import annotations

import argparse
import asyncio
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import aiomqtt
from rich.console import Console
from rich.live import Live

from odocan.host.cli.options import (
    add_duration_argument,
    add_judge_arguments,
    add_robot_argument,
    check_log_path,
    int_in,
)
from odocan.host.cli.subparsers.analyze import load_judges_dbc
from odocan.host.io.buses import add_bus_arguments, open_bus
from odocan.host.io.busreader import lost_here_text
from odocan.host.io.export import FOXGLOVE_PORT
from odocan.host.judge.monitor import BusMonitor, to_json
from odocan.host.judge.robotsource import DEFAULT_ROBOT
from odocan.host.judge.watchend import end_watch
from odocan.host.judge.watchline import Watched, watch_verdict
from odocan.host.judge.watchverdict import nothing_judged
from odocan.host.mqtt.broker import (
    BrokerError,
    BrokerURL,
    connect_failure,
    first_error,
    tls_diagnosis,
)
from odocan.host.mqtt.fleetview import RobotState, fleet_snapshot, fleet_states
from odocan.host.mqtt.options import add_broker_credentials, monitor_broker_url
from odocan.host.report.live import render_fleet, with_staleness
from odocan.host.report.trace import FrameFilter, Trace
from odocan.host.report.tui import View
from odocan.host.report.tui_app import FrameLog, MonitorApp, RecordingError, run_screen
from odocan.host.stopped import Stopped, early_stop, interruption, signum_of
from odocan.sim import interrupts, robot
from odocan.sim.exceptions import ConfigurationError, OdocanError
from odocan.sim.realtime import StopRequest, stop_on_signals

if TYPE_CHECKING:
    from odocan.host.report.foxglove import FoxgloveLive

DEFAULT_BROKER = "mqtt://127.0.0.1:1883"
REFRESH_S = 0.25  # screen redraws
RECONNECT_S = 1.0  # wait before reconnecting to the broker
TLS_CHECK_S = 5.0  # the TLS handshake checked before watching an mqtts:// broker
FIRST_CONNECT_S = 5.0  # a broker never reached in this long: an error (the bridge's
# --connect-timeout default); once reached, the watch reconnects for as long as it runs


class BrokerUnreachable(OdocanError):
    """The MQTT broker could not be reached during the whole watch."""


def add_subparser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``odocan monitor``."""
    parser = subparsers.add_parser(
        "monitor",
        help="watch a live CAN bus (or an MQTT fleet) in the terminal",
        description="Decode a live CAN bus with the DBC: per message the latest signal values, "
        "rate, period jitter and E2E counts; the firmware's status; the on-board pose against "
        "the float64 reference and the ground truth. Ctrl-C quits: exit 0, or 1 when the "
        "on-board pose was wrong at any time of the watch.",
        epilog="Example: odocan monitor -i socketcan -c vcan0; "
        "odocan monitor -i virtual -c vcan0 --duration 5 --json; "
        "odocan monitor --broker mqtt://127.0.0.1:1883",
    )
    add_duration_argument(parser)
    parser.add_argument(
        "--json",
        action="store_true",
        help="no live view: print one JSON object of the model at the end",
    )
    parser.add_argument(
        "--foxglove", nargs="?", type=int_in(1, 65535), const=FOXGLOVE_PORT, metavar="PORT",
        help=f"also serve what is heard live to Foxglove on 127.0.0.1:PORT (default "
        f"{FOXGLOVE_PORT}): poses, transforms, errors, decoded signals (default: off)",
    )
    parser.add_argument(
        "--filter",
        action="append",
        default=[],
        metavar="NAME|0xID",
        help="trace only these messages (DBC name or CAN ID; repeatable, comma-separated); "
        "'f' edits it live",
    )
    parser.add_argument(
        "--log",
        type=Path,
        metavar="PATH",
        help="record every frame heard while watching (.log candump, .asc, .blf)",
    )
    parser.add_argument(
        "--require-firmware",
        action="store_true",
        help="exit 1 when the watch heard no firmware (no cyclic ODOM_MCU message) or compared "
        "no on-board pose with the reference (or, without --robot, the firmware's PROFILE page is "
        "not the default robot's): a CI watch that judged nothing fails (default: "
        "off, so that the monitor views or records (--log) any bus; NO FIRMWARE exits 0)",
    )
    add_robot_argument(parser, role="profile for the reference", live=True)
    add_judge_arguments(parser)
    parser.add_argument(
        "--broker",
        "--mqtt",
        dest="mqtt",
        nargs="?",
        const=DEFAULT_BROKER,
        metavar="URL",
        help="show the fleet published on this MQTT broker instead of a CAN bus; without URL "
        f"{DEFAULT_BROKER} (--mqtt: alias) (default: a CAN bus)",
    )
    add_broker_credentials(parser.add_argument_group("MQTT credentials (with --broker)"))
    add_bus_arguments(parser)
    parser.set_defaults(func=_do_monitor)


def _do_monitor(args: argparse.Namespace) -> int:
    if args.mqtt is not None:
        if args.interface is not None or args.channel is not None:
            raise ConfigurationError("--broker watches MQTT: give no -i/--interface or -c")
        return _watch_fleet(monitor_broker_url(args), args)
    if args.ca or args.cert or args.key or args.password_file:
        raise ConfigurationError("--ca/--cert/--key/--password-file go with --broker URL")
    profile = robot.load(args.robot or DEFAULT_ROBOT)
    model = BusMonitor(
        profile,
        args.integrator,
        load_judges_dbc(args.dbc) if args.dbc is not None else None,
        bitrate=args.bitrate,  # -b: the bus load as a fraction of the wire
        from_page=args.robot is None,  # the firmware's PROFILE page picks (host.judge.liverobot)
    )
    trace = Trace(model.db, FrameFilter.parse(args.filter, model.db))
    check_log_path(args.log)
    stop = StopRequest()
    with stop_on_signals(stop):  # from the log's opening to its end: a signal only asks
        if stop.stop_requested:  # heard earlier, its exception lost in a library (interrupts)
            raise interruption(stop.signum, "before its watch" + (
                "" if args.log is None else f"; --log {args.log}: not written"))
        recorder = FrameLog(args.log) if args.log is not None else None
        started_s = time.monotonic()
        view = View(_source(args), interface=args.interface, log_path=args.log,
                    started_s=started_s)
        failure, signum, received = _watch_bus(args, model, trace, view, recorder,
                                               lambda: _foxglove(args, profile, model), stop)
    if signum is None and stop.stop_requested:  # heard as the watch ended: the log finished
        raise interruption(stop.signum, "after its watch, before its verdict")
    model.release_held()  # frames held for the evidence are judged now (host.judge.livesettle)
    end_watch(model.tracker, model.distance)  # what still waits judged (host.judge.watchend)
    code = _end(args, lambda: {**model.snapshot(), "receive": received},
                early_stop(signum, started_s, args.duration))
    if lost := lost_here_text(received):  # this process's own losses, not the bus's
        print(f"monitor: lost here: {lost}", file=sys.stderr)
    if failure is not None:
        raise failure
    if said := model.robot.said("odocan monitor"):  # the PROFILE page chose the robot
        print(said, file=sys.stderr)
    if said := model.pace.said("monitor"):  # a sped-up replay (host.judge.livepace)
        print(said, file=sys.stderr)
    failed = _say_verdict(args, model, model.robot.profile, time.monotonic() - started_s)
    return 1 if failed and code == 0 else code


def _say_verdict(args: argparse.Namespace, model: BusMonitor, profile: robot.RobotProfile,
                 watched_s: float) -> bool:
    """Print the watch's verdict on stderr (``host.judge.watchline``, the bridge's: a FAIL line
    per reason, else one PASS or UNJUDGED line; nothing for a watch that heard no firmware
    without ``--require-firmware``: its JSON says NO FIRMWARE) and the PROFILE page's
    mismatch; whether it FAILed."""
    judged_as = (f"{model.robot.judged_as()}{_robot_hint(args, profile, model.robot.given_as)}"
                 if model.tracker.wrongs.count else "")  # (the hint reads the whole --log)
    name, reasons = watch_verdict(Watched(
        model.tracker, model.distance, model.twist, model.sources, model.kept, model.db,
        model.messages, model.e2e.counts(), model.robot.unjudged, watched_s,
        tuple(model.ahead.why())),
        judged_as=judged_as, require_firmware=args.require_firmware)
    silent = name == "UNJUDGED" and not model.robot.unjudged and nothing_judged(
        model.db, model.messages, model.tracker.vs_reference.samples)  # no firmware: as before
    for line in [] if silent else reasons:
        print(f"monitor: {name}: {line}", file=sys.stderr)
    fails = name == "FAIL"
    if args.interface == "odocan" and not model.frames_total:
        print("monitor: heard no frame: the odocan interface carries frames within one process "
              "only; watch a bus other processes share (udp_multicast, socketcan)",
              file=sys.stderr)
    said = model.status.get("profile_mismatch")  # the firmware's PROFILE page vs --robot
    if said:
        print(f"monitor: {said}", file=sys.stderr)
    return bool(fails)


def _robot_hint(args: argparse.Namespace, profile: robot.RobotProfile, given_as: str) -> str:
    """With ``--log``: ``; robot mismatch: ...`` when the heard poses fit another shipped
    profile and not ``profile`` (a firmware set up for another robot reads as wrong), named
    ``given_as`` (``liverobot.LiveRobot.given_as``)."""
    if args.log is None:
        return ""
    from odocan.host.io.logs import read_log
    from odocan.host.judge.analysis import Tolerance
    from odocan.host.judge.diagnosis import logged_integrator, robot_mismatch

    try:
        heard = read_log(args.log, warn=lambda _text: None)
    except OdocanError:
        return ""
    integrator = args.integrator or logged_integrator(heard) or "exact"
    hint = robot_mismatch(heard, profile, integrator, Tolerance(), given_as)
    return "" if hint is None else "; " + hint.replace("the log's poses", "the heard poses")


def _end(args: argparse.Namespace, snapshot: Callable[[], dict[str, Any]],
         stopped: Stopped | None) -> int:
    """The watch's end: its JSON snapshot when asked (with ``stopped``: a signal ended it before
    ``--duration``), the early stop said on stderr; returns the exit code (0, or the signal's)."""
    if args.json:
        data = snapshot()
        if stopped is not None:
            data["stopped"] = stopped.as_dict()
        print(to_json(data))
    if stopped is not None:
        print(f"monitor: {stopped.text()}", file=sys.stderr)
    return 0 if stopped is None else stopped.exit_code


def _watch_bus(
    args: argparse.Namespace, model: BusMonitor, trace: Trace, view: View,
    recorder: FrameLog | None, start_live: Callable[[], FoxgloveLive | None], stop: StopRequest,
) -> tuple[RecordingError | None, int | None, dict[str, int | None]]:
    """Watch the bus until the deadline, ``q``, Ctrl-C or SIGTERM (``stop`` asked, even before
    the receive loop runs, or a second signal); the recording's error, returned so that what
    was heard is still shown (``--json``) before the command ends with it, the signal that
    ended it, if one did, and what was read and lost here (``BusReader.stats``, with
    ``recorded``: the frames in ``--log``, None without). ``recorder`` is finished whatever
    happens; ``start_live()``: the live Foxglove server, if asked, closed at the end."""
    failure: RecordingError | None = None
    signum: int | None = None
    received: dict[str, int | None] = {}
    live: FoxgloveLive | None = None
    try:
        live = start_live()
        bus = open_bus(args)
        try:
            app = MonitorApp(bus, model, trace, view, recorder,
                             None if live is None else live.publish, stop)
            if args.json:
                app.receive(_deadline(args.duration))
            else:
                run_screen(app, _deadline(args.duration))
            signum = app.stopped_by
            received = {} if app.reader is None else app.reader.stats()
        finally:
            bus.shutdown()
    except KeyboardInterrupt as exc:  # a second signal before the loop took it: the same way
        signum = stop.signum or signum_of(exc)
    finally:
        if recorder is not None:
            try:
                recorder.close()
            except RecordingError as exc:
                failure = exc
        if live is not None:
            live.close()
    received["recorded"] = None if recorder is None else recorder.count
    return failure, signum, received


def _foxglove(
    args: argparse.Namespace, profile: robot.RobotProfile, model: BusMonitor
) -> FoxgloveLive | None:
    """``--foxglove``: a live Foxglove server fed by this monitor's own model (its line on
    stderr says where to connect); None without the option."""
    if args.foxglove is None:
        return None
    from odocan.host.report.foxglove import FoxgloveLive

    live = FoxgloveLive(profile, port=args.foxglove, monitor=model)
    print(f"foxglove: serving on {live.url}: in Foxglove, Open connection > Foxglove WebSocket "
          f"> {live.url}", file=sys.stderr, flush=True)
    return live


def _source(args: argparse.Namespace) -> str:
    return ":".join(str(v) for v in (args.interface or "python-can default", args.channel) if v)


def _deadline(duration_s: float | None) -> float:
    return math.inf if duration_s is None else time.monotonic() + duration_s


# --- the fleet over MQTT ----------------------------------------------------------------------


def _watch_fleet(url: BrokerURL, args: argparse.Namespace) -> int:
    """The fleet table until the deadline or Ctrl-C; ``--json``: one object at the end."""
    watch = _FleetWatch(url, args.duration)
    signum: int | None = None
    try:
        if args.json:
            asyncio.run(watch.run(None))
        else:
            console = Console(file=sys.stdout)
            try:
                with Live(console=console, auto_refresh=False) as live:
                    asyncio.run(watch.run(lambda: live.update(watch.render(), refresh=True)))
            finally:
                if not console.is_terminal:  # the last screen ends its line before any error's
                    console.line()
    except KeyboardInterrupt as exc:  # before or after the watch's loop took the signals
        signum = signum_of(exc)
    except BaseExceptionGroup as group:  # the watch's TaskGroup: its one-line error, not a tree
        raise first_error(group) from None
    signum = signum or watch.signum
    if not watch.connected_once:  # no error at all: something took the TCP connection, silent
        reason = watch.last_error or (f"no MQTT answer in {time.monotonic() - watch.started:.1f}"
                                      " s (is it an MQTT broker?)")
        raise BrokerUnreachable(f"cannot reach the MQTT broker {url}: {reason}")
    return _end(args, watch.snapshot, early_stop(signum, watch.started, args.duration))


class _FleetWatch:
    """The latest fleet table, kept across reconnections."""

    def __init__(self, url: BrokerURL, duration_s: float | None) -> None:
        self.url, self.duration_s = url, duration_s
        self.table: dict[str, RobotState] = {}
        self.connected_once = False
        self.last_error = ""
        self.started = time.monotonic()
        self.signum: int | None = None  # SIGINT or SIGTERM, when one ended the watch

    async def run(self, redraw: Callable[[], None] | None) -> None:
        """Follow the broker until the duration has passed (forever without one) or SIGINT or
        SIGTERM (``signum``); a TLS or credentials problem at the first connection is a
        ``BrokerError`` at once (no retry mends it). The signals are the loop's: raised in the
        task reading the broker, one was left there ("Task exception was never retrieved") and
        its MQTT client closed after the loop ("Event loop is closed")."""
        watching = asyncio.current_task()
        assert watching is not None

        def on_signal(signum: int) -> None:
            self.signum = self.signum or signum
            watching.cancel()

        with interrupts.loop_handlers_installed(asyncio.get_running_loop(), on_signal):
            if (latched := interrupts.latched()) is not None:  # heard as the command started
                on_signal(latched)
            try:
                await self._watch(redraw)
            except asyncio.CancelledError:
                if self.signum is None:
                    raise
                watching.uncancel()

    async def _watch(self, redraw: Callable[[], None] | None) -> None:
        if self.url.tls and (found := await tls_diagnosis(self.url, TLS_CHECK_S)) is not None:
            raise BrokerError(f"cannot connect to {self.url}: TLS: {found}")
        try:
            async with asyncio.timeout(self.duration_s), asyncio.TaskGroup() as tasks:
                tasks.create_task(self._follow(redraw), name="follow-broker")
                if redraw is not None:  # the clock and staleness move without messages too
                    tasks.create_task(self._tick(redraw), name="redraw")
        except TimeoutError:
            pass

    @staticmethod
    async def _tick(redraw: Callable[[], None]) -> None:
        while True:
            redraw()
            await asyncio.sleep(REFRESH_S)

    async def _follow(self, redraw: Callable[[], None] | None) -> None:
        while True:
            if redraw is not None:
                redraw()
            try:
                async for table in fleet_states(broker=self.url, min_interval_s=REFRESH_S):
                    self.connected_once, self.last_error = True, ""
                    self.table = table
                    if redraw is not None:
                        redraw()
            except aiomqtt.MqttError as exc:
                self.last_error = str(exc) or type(exc).__name__
                reason = connect_failure(exc, TLS_CHECK_S, tls=self.url.tls,
                                         client_cert=self.url.cert is not None)
                if not self.connected_once and reason.startswith(("not authorized", "TLS:")):
                    raise BrokerError(f"cannot connect to {self.url}: {reason}") from None
                if not self.connected_once and \
                        time.monotonic() - self.started >= FIRST_CONNECT_S:  # a wrong URL
                    raise BrokerUnreachable(f"cannot reach the MQTT broker {self.url}: "
                                            f"{reason} (for {FIRST_CONNECT_S:g} s)") from None
            await asyncio.sleep(RECONNECT_S)

    def snapshot(self) -> dict[str, Any]:
        """``broker``, ``duration_s`` and ``robots`` (``host.monitor.fleet_snapshot``, with each
        robot's ``age_s`` and ``stale`` as the screen marks them)."""
        return {
            "broker": str(self.url),
            "duration_s": time.monotonic() - self.started,
            "robots": with_staleness(fleet_snapshot(self.table), time.time()),
        }

    def render(self) -> Any:
        """The screen (with the connection problem, if any)."""
        note = f"broker: {self.last_error} (reconnecting)" if self.last_error else ""
        return render_fleet(
            fleet_snapshot(self.table),
            source=str(self.url),
            elapsed_s=time.monotonic() - self.started,
            note=note,
        )
