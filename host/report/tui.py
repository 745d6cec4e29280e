"""The terminal UI of ``odocan monitor``: a screen that fits 80×24 and grows with the terminal.

Why rich with a ``Layout`` and not textual: rich is already a dependency and the model's tables
are rich renderables (``host.report.live``); a ``Layout`` gives every region a height of its own,
so what matters (firmware state, pose against reference and truth) is placed first and can never
be pushed off the screen by a long table, and the screen stays a pure function
``screen(snapshot, trace, ...)`` that a test renders on a fixed-size ``Console`` and that records
to SVG as it is. The receive loop stays the plain synchronous python-can loop it was (no second
event loop next to ``bus.recv``); the few keys (pause, filter, quit) are read from the terminal in
cbreak mode between frames.

The screen, top to bottom (rows on 80×24)::

    header       source, time, frames, bus load, PAUSED, the trace filter             1
    verdict      the judge's verdict (OK, STALE, CONFLICT, DEGRADED, POSE WRONG) and why 1
    firmware     STATE, AUTH refusals (SecOC), reason, status age, integrator, uptime 1
    pose         on-board / reference / truth, on-board minus each (latest and max)   4
    alert        nothing heard for 2 s and why, node events, frames not checked       1
    messages     rate, jitter, E2E, and per-page rates of multiplexed messages      ≥ 4
    trace        the latest decoded frames, filtered, frozen while paused          the rest
    keys         space/p pause, f filter, q quit; the --log file and its count        1

A terminal of 40 rows or more also shows the latest signal values of every message; one of
150 columns or more puts the trace beside the message table.

Per-page rates are counted here, from the frames the trace decodes (every frame is decoded
whether or not it is shown), not by the model: ``PageRates``.
"""

from __future__ import annotations

import os
import select
import sys
import termios
import time
import tty
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import can
from cantools.database.can import Database, Message
from cantools.database.namedsignalvalue import NamedSignalValue
from rich.console import Console, ConsoleOptions, Group, RenderableType, RenderResult
from rich.layout import Layout
from rich.live import Live
from rich.segment import Segment
from rich.table import Table
from rich.text import Text

from odocan.host.judge.monitor import BusMonitor
from odocan.host.protocol.decode import frame_key
from odocan.host.report.live import (
    BAD_VERDICTS,
    STALE_S,
    compact_table,
    num,
    pose_table,
    unknown_line,
    values_text,
)
from odocan.sim.exceptions import ConfigurationError, OdocanError

SILENCE_S = 2.0  # nothing heard for this long: the warning line says so, and why it may be
STATUS_STALE_S = 2.0  # an ODOM_STATUS older than this: the firmware line says STALE
TRACE_LINES = 500  # decoded frames kept for the trace
PAGE_WINDOW = 32  # frames per page for a page's rate
REFRESH_S = 0.25  # screen redraws
TOP_ROWS = 8  # header, verdict, firmware, pose (4), alert
BUS_LOAD_WARN = 0.7  # the header's bus load turns red above this (a common design limit)
WIDE_COLUMNS = 150  # from this width the trace sits beside the message table
TALL_ROWS = 40  # from this height the latest signal values are shown too
_HIDDEN = frozenset({"CHECKSUM", "COUNTER"})


# --- what the trace sees ----------------------------------------------------------------------


@dataclass(frozen=True)
class FrameFilter:
    """Which frames the trace shows: by message name or by CAN ID (empty: all)."""

    names: frozenset[str] = frozenset()
    ids: frozenset[int] = frozenset()
    text: str = ""

    @classmethod
    def parse(cls, specs: Sequence[str], db: Database) -> FrameFilter:
        """``NAME`` (a DBC message, any case) or ``0xID`` items, also comma-separated."""
        names, ids = set(), set()
        known = {m.name.upper() for m in db.messages}
        items = [item.strip() for spec in specs for item in spec.split(",") if item.strip()]
        for item in items:
            if item.lower().startswith("0x"):
                try:
                    ids.add(int(item, 16))
                except ValueError:
                    raise ConfigurationError(f"--filter {item}: not a hexadecimal CAN ID") from None
            elif item.upper() in known:
                names.add(item.upper())
            else:
                raise ConfigurationError(
                    f"--filter {item}: no such message in the DBC (give a name or 0xID)")
        return cls(frozenset(names), frozenset(ids), ",".join(items))

    def matches(self, arbitration_id: int, name: str | None) -> bool:
        """True when the frame is shown."""
        if not self.names and not self.ids:
            return True
        return arbitration_id in self.ids or (name is not None and name.upper() in self.names)


class PageRate(NamedTuple):
    """One page of a multiplexed message: its multiplexer value, name and rate (Hz)."""

    number: int
    name: str
    rate_hz: float | None  # None before two frames


@dataclass
class PageRates:
    """Frame rate of each page of each multiplexed message, from bus timestamps."""

    times: dict[tuple[str, int], deque[float]] = field(default_factory=dict)
    names: dict[tuple[str, int], str] = field(default_factory=dict)

    def heard(self, message: str, number: int, name: str, timestamp_s: float) -> None:
        """One frame of ``message``'s page ``number`` (``name``) at ``timestamp_s`` (bus, s)."""
        key = (message, number)
        if key not in self.times:
            self.times[key] = deque(maxlen=PAGE_WINDOW)
            self.names[key] = name
        self.times[key].append(timestamp_s)

    def rates_hz(self, message: str) -> list[PageRate]:
        """The pages heard of ``message``, by multiplexer value, with their rates."""
        out = []
        for (name, number), times in sorted(self.times.items()):
            if name == message:
                span_s = times[-1] - times[0]
                rate_hz = (len(times) - 1) / span_s if len(times) > 1 and span_s > 0 else None
                out.append(PageRate(number, self.names[(name, number)], rate_hz))
        return out


@dataclass(frozen=True)
class TraceLine:
    """One decoded frame as the trace shows it."""

    timestamp_s: float
    arbitration_id: int
    name: str  # "?" when the ID is not in the DBC
    text: str


class Trace:
    """The latest decoded frames (filtered, frozen while paused) and the per-page rates."""

    def __init__(self, db: Database, frame_filter: FrameFilter | None = None,
                 lines: int = TRACE_LINES) -> None:
        self.db = db
        self.filter = frame_filter or FrameFilter()
        self.lines: deque[TraceLine] = deque(maxlen=lines)
        self.pages = PageRates()
        self.paused = False
        self.hidden_while_paused = 0
        self.first_s: float | None = None  # bus time of the first frame (the trace's zero)
        self._by_key = {frame_key(m.frame_id, m.is_extended_frame): m for m in db.messages}

    def feed(self, msg: can.Message) -> None:
        """Decode one frame: count its page, and keep it unless paused or filtered out."""
        if self.first_s is None:
            self.first_s = msg.timestamp
        if msg.is_error_frame or msg.is_remote_frame:
            self._keep(msg, "?", "error frame" if msg.is_error_frame else "remote frame")
            return
        message = self._by_key.get(frame_key(msg.arbitration_id, msg.is_extended_id))
        if message is None:
            self._keep(msg, "?", bytes(msg.data).hex(" "))
            return
        text, page = _decoded(message, bytes(msg.data))
        if page is not None:
            self.pages.heard(message.name, *page, msg.timestamp)
        self._keep(msg, message.name, text)

    def _keep(self, msg: can.Message, name: str, text: str) -> None:
        if not self.filter.matches(msg.arbitration_id, None if name == "?" else name):
            return
        if self.paused:
            self.hidden_while_paused += 1
            return
        self.lines.append(TraceLine(msg.timestamp, msg.arbitration_id, name, text))

    def toggle_pause(self) -> None:
        """Freeze or resume the trace (the statistics never stop)."""
        self.paused = not self.paused
        self.hidden_while_paused = 0


def _decoded(message: Message, data: bytes) -> tuple[str, tuple[int, str] | None]:
    """The frame's signals as text, and its page (number, name) when it is multiplexed."""
    try:
        signals = message.decode(data, decode_choices=True, allow_truncated=True)
    except Exception:  # cantools: wrong length, unknown page ... (never fatal)
        return f"undecodable {data.hex(' ')}", None
    assert isinstance(signals, dict)
    page = None
    muxes = [s.name for s in message.signals if s.is_multiplexer]
    if muxes and muxes[0] in signals:
        value = signals[muxes[0]]
        number = value.value if isinstance(value, NamedSignalValue) else value
        page = (int(number), str(value))
    parts = []
    for name, value in signals.items():
        if name in _HIDDEN:
            continue
        shown = f"{value:.4f}".rstrip("0").rstrip(".") if isinstance(value, float) else str(value)
        parts.append(f"{name} {shown}")
    return " ".join(parts), page


# --- the screen --------------------------------------------------------------------------------


@dataclass
class View:
    """What the screen shows besides the model's snapshot (times are local monotonic, s)."""

    source: str
    interface: str | None = None
    now_s: float = 0.0
    started_s: float = 0.0
    last_frame_s: float | None = None  # when the last frame was heard (None: never)
    heard_s: dict[str, float] = field(default_factory=dict)  # message -> seconds since heard
    log_path: Path | None = None
    logged: int = 0
    log_error: str = ""
    editing: str | None = None  # the filter being typed (None: not editing)
    note: str = ""  # a one-off message (e.g. a refused filter)


def screen(snapshot: dict[str, Any], trace: Trace, view: View, *, width: int = 80,
           height: int = 24) -> Layout:
    """The whole screen for a terminal of ``width`` × ``height`` (see the module docstring)."""
    layout = Layout(name="screen")
    body = Layout(name="body")
    layout.split_column(
        Layout(_top(snapshot, trace, view), name="top", size=TOP_ROWS),
        body,
        Layout(_keys_line(trace, view), name="keys", size=1),
    )
    trace_view = _TraceView(trace)
    body_rows = max(2, height - TOP_ROWS - 1)
    rows_wanted = 1 + len(snapshot["messages"])
    messages_width = min(110, width // 2) if width >= WIDE_COLUMNS else width
    messages = _Fit(messages_table(snapshot, trace.pages, view.heard_s, width=messages_width))
    if width >= WIDE_COLUMNS:
        body.split_row(Layout(messages, name="messages", size=messages_width),
                       Layout(trace_view, name="trace"))
    elif height >= TALL_ROWS:
        values = values_table(snapshot, view.heard_s)
        body.split_column(
            Layout(messages, name="messages", size=min(rows_wanted, body_rows // 3)),
            Layout(_Fit(values), name="values", size=min(rows_wanted + 1, body_rows // 3)),
            Layout(trace_view, name="trace"),
        )
    else:
        size = min(rows_wanted, max(4, (body_rows + 1) // 2 + 1))
        body.split_column(Layout(messages, name="messages", size=size),
                          Layout(trace_view, name="trace"))
    return layout


def _top(snapshot: dict[str, Any], trace: Trace, view: View) -> RenderableType:
    return Group(
        _header(snapshot, trace, view),
        verdict_line(snapshot),
        firmware_line(snapshot, view.heard_s.get("ODOM_STATUS")),
        _pose_rows(snapshot),
        alert_line(snapshot, view),
    )


def _header(snapshot: dict[str, Any], trace: Trace, view: View) -> Text:
    text = Text.assemble(
        ("odocan monitor ", "bold"), (view.source, "cyan"),
        f"  {view.now_s - view.started_s:.1f} s  {snapshot['frames_total']} frames",
        no_wrap=True, overflow="ellipsis",
    )
    if trace.paused:  # what the keys changed comes first: it must not be cut off on 80 columns
        text.append("  PAUSED", style="bold reverse yellow")
    if trace.filter.text:
        text.append(f"  filter {trace.filter.text}", style="magenta")
    load = snapshot.get("bus_load") or {}
    if load.get("load") is not None:
        style = "bold red" if load["load"] > BUS_LOAD_WARN else ""
        text.append(f"  bus {load['load']:.0%}", style=style)
    elif load.get("bits_per_s") is not None:
        text.append(f"  bus {load['bits_per_s'] / 1000:.1f} kbit/s")
    return text


def verdict_line(snapshot: dict[str, Any]) -> Text:
    """The judge's verdict and why (``health`` in the snapshot): it never says OK while the pose
    shown may be wrong (STALE, CONFLICT, the firmware's DEGRADED/FAULT, POSE WRONG, ...)."""
    health = snapshot.get("health")
    line = Text(no_wrap=True, overflow="ellipsis")
    line.append("verdict ", style="bold")
    if not health:
        line.append("none from the model", style="dim")
        return line
    verdict = str(health["state"])
    line.append(verdict, style="bold green" if verdict == "OK" else "bold red"
                if verdict in BAD_VERDICTS else "bold yellow")
    if health["why"]:
        line.append(f": {'; '.join(health['why'])}", style="yellow")
    return line


def firmware_line(snapshot: dict[str, Any], status_age_s: float | None) -> Text:
    """``firmware STATE  reason …  age …  integrator …  uptime …`` on one line.

    The reason is the error bits the firmware reports; the age is the time since the last
    ODOM_STATUS frame (``age_s`` of the status when the model gives one); STALE past
    ``STATUS_STALE_S`` (or when the model says ``stale``).
    """
    status = snapshot.get("status") or {}
    line = Text(no_wrap=True, overflow="ellipsis")
    line.append("firmware ", style="bold")
    if not status:
        line.append("no ODOM_STATUS summary yet", style="dim")
        _append_auth(line, snapshot)
        return line
    state = str(status.get("state"))
    line.append(state, style={"OK": "bold green", "DEGRADED": "bold yellow",
                              "FAULT": "bold red"}.get(state, "bold"))
    age_s = status.get("age_s", status_age_s)
    stale = bool(status.get("stale")) or (age_s is not None and age_s > STATUS_STALE_S)
    if stale:
        line.append(" STALE", style="bold reverse red")
    _append_auth(line, snapshot)  # before the long fields: never cut off on 80 columns
    errors = status.get("errors") or []
    reason = " ".join(errors) if errors else "no error bits"
    line.append(f"  reason {reason}", style="yellow" if errors else "")
    if age_s is not None:
        line.append(f"  age {age_s:.1f} s", style="red" if stale else "")
    line.append(f"  {status.get('integrator')}  uptime {status.get('uptime_s')} s")
    return line


# snapshot["auth"] counter -> its word on the firmware line, in this order
AUTH_WORDS = {"auth_failed": "failed", "auth_freshness": "stale", "auth_missing": "missing",
              "auth_unavailable": "unavailable", "auth_without_command": "orphan"}


def auth_text(snapshot: dict[str, Any]) -> str:
    """The SecOC refusals so far, e.g. ``AUTH 5 failed 3 missing 2 orphan``: the firmware's
    NACKs by AUTH_* reason, and ODOM_AUTH frames that followed no command (``orphan``); only
    the counts above 0, and "" when there are none (or the model counts none)."""
    counts = snapshot.get("auth") or {}
    parts = [f"{counts[key]} {word}" for key, word in AUTH_WORDS.items() if counts.get(key)]
    return f"AUTH {' '.join(parts)}" if parts else ""


def _append_auth(line: Text, snapshot: dict[str, Any]) -> None:
    """The firmware line's authentication segment (bold red), when there is one."""
    text = auth_text(snapshot)
    if text:
        line.append(f"  {text}", style="bold red")


def _pose_rows(snapshot: dict[str, Any]) -> Table:
    """On-board, reference and truth (4 rows with the header, 80 columns: 3 decimals)."""
    table = pose_table(snapshot, decimals=3)
    table.box, table.show_edge = None, False
    return table


def alert_line(snapshot: dict[str, Any], view: View) -> Text:
    """The most important warning: silence (and why), a node event, else what was not checked."""
    silent_s = view.now_s - (view.last_frame_s if view.last_frame_s is not None
                             else view.started_s)
    if silent_s > SILENCE_S:
        since = "" if view.last_frame_s is None else " since the last frame"
        text = (f"nothing heard for {silent_s:.1f} s{since}: "
                f"{silence_hint(view.interface, view.last_frame_s)}")
        return Text(text, style="bold red", no_wrap=True, overflow="ellipsis")
    if view.note:
        return Text(view.note, style="yellow", no_wrap=True, overflow="ellipsis")
    events = snapshot.get("events") or (snapshot.get("health") or {}).get("events") or []
    if events:
        return Text(f"event: {_event_text(events[-1])}", style="yellow", no_wrap=True,
                    overflow="ellipsis")
    line = unknown_line(snapshot["unknown"])
    line.no_wrap, line.overflow = True, "ellipsis"
    return line


def silence_hint(interface: str | None, last_frame_s: float | None) -> str:
    """Why a bus may be silent, for the interface in use."""
    if last_frame_s is not None:
        return "the sender stopped, or the bus went down"
    if interface == "virtual":
        return ("a python-can virtual bus lives inside one process: another process's frames "
                "never arrive (use udp_multicast or socketcan)")
    if interface == "udp_multicast":
        return "is the sender on the same group and port (--bus-arg port=N) and running?"
    if interface == "socketcan":
        return "is the interface up (ip link show) and is a node sending?"
    return "is a node sending, and are the interface, channel and bitrate right?"


def _event_text(event: Any) -> str:
    if isinstance(event, dict):
        return " ".join(f"{k} {v}" for k, v in event.items())
    return str(event)


def messages_table(snapshot: dict[str, Any], pages: PageRates, heard_s: dict[str, float], *,
                   width: int = 80) -> Table:
    """Per message: ID, frames, Hz, jitter, E2E problems, and each page's rate."""
    wide = width >= 100
    table = compact_table("message", "ID", "frames", "Hz", "jit ms", "E2E", "pages Hz")
    table.box, table.show_edge = None, False
    table.expand = True
    table.columns[5].justify = table.columns[6].justify = "left"
    table.columns[6].overflow, table.columns[6].ratio = "ellipsis", 1
    for name, m in snapshot["messages"].items():
        age_s = heard_s.get(name, 0.0)
        stale = bool(m.get("stale")) or age_s > STALE_S
        table.add_row(
            name, m["id"], str(m["count"]), num(m["rate_hz"], ".1f"), num(m["jitter_ms"], ".2f"),
            _e2e_text(m["e2e"]), _pages_text(pages.rates_hz(name), wide=wide),
            style="dim" if stale else None,
        )
    return table


def values_table(snapshot: dict[str, Any], heard_s: dict[str, float]) -> Table:
    """Per message its latest signal values, one row each (cut at the edge, never wrapped)."""
    table = compact_table("message", "latest values")
    table.box, table.show_edge, table.expand = None, False, True
    table.columns[1].justify, table.columns[1].overflow, table.columns[1].ratio = (
        "left", "ellipsis", 1)
    for name, m in snapshot["messages"].items():
        table.add_row(name, values_text(m.get("last_frame", m["last"]), m["units"]),
                      style="dim" if heard_s.get(name, 0.0) > STALE_S else None)
    return table


def _e2e_text(e2e: dict[str, Any]) -> Text:
    bad = {k: v for k, v in e2e.items() if k != "ok" and v}
    if not e2e:
        return Text("-", style="dim")
    if not bad:
        return Text("ok", style="green")
    short = {"lost": "lost", "repeated": "rep", "crc_errors": "crc", "wrong_sequence": "seq"}
    return Text(" ".join(f"{short.get(k, k)} {v}" for k, v in bad.items()), style="yellow")


def _pages_text(pages: list[PageRate], *, wide: bool) -> str:
    """``X=3.33 Y=3.33 HEADING=3.33`` (Hz); a long page name is ``p<number>`` unless ``wide``."""
    parts = []
    for page in pages:
        label = page.name if wide or len(page.name) <= 7 else f"p{page.number}"
        parts.append(f"{label}={num(page.rate_hz, '.3g')}")
    return " ".join(parts)


class _Fit:
    """A renderable cut to the height its region gets (a table never spills past it)."""

    def __init__(self, renderable: RenderableType) -> None:
        self.renderable = renderable

    def __rich_console__(self, console: Console, options: ConsoleOptions) -> RenderResult:
        lines = console.render_lines(self.renderable, options.update(height=None), pad=False)
        height = options.height if options.height is not None else len(lines)
        for line in lines[:height]:
            yield from line
            yield Segment.line()


class _TraceView:
    """The newest trace lines that fit the region, below a title line."""

    def __init__(self, trace: Trace) -> None:
        self.trace = trace

    def __rich_console__(self, console: Console, options: ConsoleOptions) -> RenderResult:
        height = options.height or 10
        title = Text("trace", style="bold", no_wrap=True, overflow="ellipsis")
        zero_s = self.trace.first_s or 0.0
        if self.trace.paused:
            title.append(f" (paused, {self.trace.hidden_while_paused} not shown)", style="yellow")
        if self.trace.filter.text:
            title.append(f" filter {self.trace.filter.text}", style="magenta")
        title.append("  (time: s since the first frame)", style="dim")
        yield title
        for line in list(self.trace.lines)[-(height - 1):] if height > 1 else []:
            yield Text.assemble(
                f"{line.timestamp_s - zero_s:8.3f} ", (f"{line.arbitration_id:03X} ", "cyan"),
                (f"{line.name:<14.14} ", "bold"), line.text, no_wrap=True, overflow="ellipsis",
            )


def _keys_line(trace: Trace, view: View) -> Text:
    if view.editing is not None:
        return Text(f"filter (names or 0xIDs, Enter applies, Esc cancels): {view.editing}_",
                    style="reverse", no_wrap=True, overflow="ellipsis")
    line = Text("space/p ", style="bold", no_wrap=True, overflow="ellipsis")
    line.append("resume" if trace.paused else "pause")
    line.append("  f ", style="bold")
    line.append("filter")
    line.append("  q ", style="bold")
    line.append("quit")
    if view.log_path is not None:
        line.append(f"  log {view.logged} frames to {view.log_path}", style="cyan")
    if view.log_error:
        line.append(f"  log stopped: {view.log_error}", style="bold red")
    return line


# --- the app ----------------------------------------------------------------------------------


class RecordingError(OdocanError):
    """``--log``: the recording could not be written (disk full, file gone, ...)."""


class Recorder:
    """``--log PATH``: every frame heard to python-can's ``can.Logger`` (.log/.asc/.blf).

    A write error stops the recording (the keys line says so) but never the monitor; ``close()``
    then raises ``RecordingError`` naming the path and the frames written, so the command ends
    with one ``error:`` line and exit code 2 rather than a recording silently cut short.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.count = 0
        self.failure: Exception | None = None
        try:
            self._logger = can.Logger(path)
        except (OSError, ValueError) as exc:
            raise ConfigurationError(f"--log {path}: {exc}") from exc

    def record(self, msg: can.Message) -> None:
        """Write one frame (counted when written); after a failure, nothing more."""
        if self.failure is not None:
            return
        try:
            self._logger.on_message_received(msg)
        except Exception as exc:  # any writer's error stops the recording, not the monitor
            self.failure = exc
            return
        self.count += 1

    @property
    def error(self) -> str:
        """The write error that stopped the recording ("" while recording)."""
        exc = self.failure
        return "" if exc is None else f"{type(exc).__name__}: {exc}"

    def close(self) -> None:
        """Finalise the file (a .blf's header and index are written here)."""
        try:
            self._logger.stop()
        except Exception as exc:
            self.failure = self.failure or exc
        if self.failure is not None:
            raise RecordingError(f"--log {self.path}: recording stopped after {self.count} "
                                 f"frames: {self.error}")


class MonitorApp:
    """The receive loop behind the screen: feed the model, the trace and the log; read keys."""

    def __init__(self, bus: can.BusABC, model: BusMonitor, trace: Trace, view: View,
                 recorder: Recorder | None = None,
                 publish: Callable[[can.Message], None] | None = None) -> None:
        """``publish``: called with every frame after the model took it (live Foxglove)."""
        self.bus, self.model, self.trace, self.view = bus, model, trace, view
        self.recorder = recorder
        self.publish = publish
        self.quit = False

    def receive(self, deadline_s: float, redraw: Any | None = None) -> None:
        """Until ``deadline_s`` (monotonic), ``q`` or Ctrl-C; ``redraw()`` every ``REFRESH_S``."""
        next_draw = 0.0
        try:
            while not self.quit and (now := time.monotonic()) < deadline_s:
                if redraw is not None and now >= next_draw:
                    redraw()
                    next_draw = now + REFRESH_S
                msg = self.bus.recv(timeout=max(0.0, min(REFRESH_S, deadline_s - now)))
                if msg is not None:
                    self.on_frame(msg)
                if redraw is not None:
                    self.on_keys(_read_keys())
        except KeyboardInterrupt:
            pass

    def on_frame(self, msg: can.Message) -> None:
        """One frame heard: log it, feed the model and the trace."""
        self.view.last_frame_s = time.monotonic()
        if self.recorder is not None:
            self.recorder.record(msg)
        self.model.feed(msg)
        self.trace.feed(msg)
        if self.publish is not None:
            self.publish(msg)

    def on_keys(self, keys: str) -> None:
        """space/p: pause; f: edit the filter (Enter applies, Esc cancels); q: quit."""
        for key in keys:
            if self.view.editing is not None:
                self._edit(key)
            elif key in " p":
                self.trace.toggle_pause()
            elif key == "f":
                self.view.editing, self.view.note = self.trace.filter.text, ""
            elif key == "q":
                self.quit = True

    def _edit(self, key: str) -> None:
        text = self.view.editing or ""
        if key in "\r\n":
            try:
                self.trace.filter = FrameFilter.parse([text], self.trace.db)
                self.trace.lines.clear()
            except ConfigurationError as exc:
                self.view.note = str(exc)
            self.view.editing = None
        elif key == "\x1b":
            self.view.editing = None
        elif key in "\x7f\b":
            self.view.editing = text[:-1]
        elif key.isprintable():
            self.view.editing = text + key

    def refresh_view(self) -> None:
        """Bring the view's clock, ages and log count up to now."""
        now = time.monotonic()
        self.view.now_s = now
        self.view.heard_s = {n: now - s.heard_monotonic_s for n, s in self.model.messages.items()}
        if self.recorder is not None:
            self.view.logged, self.view.log_error = self.recorder.count, self.recorder.error


def run_screen(app: MonitorApp, deadline_s: float, console: Console | None = None) -> None:
    """Show the screen until the deadline, ``q`` or Ctrl-C.

    On a terminal it takes the whole (alternate) screen, and its last state is printed once more
    after it closes, so it stays in the scrollback; elsewhere only the last state is printed."""
    console = console or Console(file=sys.stdout)

    def current(spare_rows: int = 0) -> Layout:
        app.refresh_view()
        width, height = console.size
        return screen(app.model.snapshot(), app.trace, app.view, width=width,
                      height=height - spare_rows)

    with _cbreak(), Live(console=console, auto_refresh=False, screen=console.is_terminal,
                         redirect_stderr=False) as live:
        app.receive(deadline_s, lambda: live.update(current(), refresh=True))
        live.update(current(), refresh=True)
    if console.is_terminal:
        console.print(current(spare_rows=1), height=console.size.height - 1)  # + the prompt


@contextmanager
def _cbreak() -> Iterator[None]:
    """Keys arrive one by one without echo while the screen is up (no-op without a tty)."""
    try:
        fd = sys.stdin.fileno()
        saved = termios.tcgetattr(fd) if os.isatty(fd) else None
    except (OSError, ValueError, termios.error):
        saved = None
    if saved is None:
        yield
        return
    tty.setcbreak(fd)
    try:
        yield
    finally:
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)


def _read_keys() -> str:
    """Whatever keys are waiting on a terminal's stdin ("" otherwise; never blocks)."""
    try:
        fd = sys.stdin.fileno()
        if not os.isatty(fd) or not select.select([fd], [], [], 0)[0]:
            return ""
        return os.read(fd, 64).decode("utf-8", "replace")
    except (OSError, ValueError):
        return ""
