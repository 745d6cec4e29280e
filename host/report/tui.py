"""The terminal UI of ``odocan monitor``: a screen that fits 80×24 and grows with the terminal.

Why rich with a ``Layout`` and not textual: rich is already a dependency and the model's tables
are rich renderables (``host.report.live``); a ``Layout`` gives every region a height of its own,
so what matters (firmware state, pose against reference and truth) is placed first and can never
be pushed off the screen by a long table, and the screen stays a pure function
``screen(snapshot, trace, ...)`` that a test renders on a fixed-size ``Console`` and that records
to SVG as it is. The judging loop stays a plain synchronous loop (no event loop): it takes the
frames that a reader thread (``host.io.busreader``) read and already wrote to ``--log``, so a slow
judge or screen never makes the recording lose a frame; the few keys (pause, filter, quit) are
read from the terminal in cbreak mode between frames.

The screen, top to bottom (rows on 80×24)::

    header       source, time, frames, bus load, PAUSED, the trace filter             1
    verdict      the judge's verdict (OK, STALE, CONFLICT, DEGRADED, POSE WRONG), WAS WRONG
                 (the pose was wrong earlier: latched, the worst episode) and why         1
    firmware     STATE, AUTH refusals (SecOC), the robot its PROFILE page chose (not  1
                 the default pmir), reason, status age, integrator, uptime
    pose         on-board / reference / truth, on-board minus each (latest and max)   4
    alert        nothing heard for 2 s and why, node events, frames not checked       1
    messages     rate, jitter, E2E, and per-page rates of multiplexed messages      ≥ 4
    trace        the latest decoded frames, filtered, frozen while paused          the rest
    keys         space/p pause, f filter, q quit; the --log file and its count; the
                 frames lost here (dropped by the socket, not judged), if any         1

A terminal of 40 rows or more also shows the latest signal values of every message; one of
150 columns or more puts the trace beside the message table.

Three modules by job: this one is the screen (the view state ``View`` and the pure ``screen``
with its lines and tables); ``host.report.trace`` is what the trace sees (decoding, the filter,
the per-page rates, counted from the frames the trace decodes, every frame whether or not it is
shown, not by the model: ``PageRates``); ``host.report.tui_app`` is the app (the receive loop,
``--log``, the keys, the live terminal).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rich.console import Console, ConsoleOptions, Group, RenderableType, RenderResult
from rich.layout import Layout
from rich.segment import Segment
from rich.table import Table
from rich.text import Text

from odocan.host.judge.robotsource import DEFAULT_ROBOT, FROM_PAGE
from odocan.host.protocol.e2e_silence import SILENCE_KEYS, lost_text
from odocan.host.report.live import (
    BAD_VERDICTS,
    STALE_S,
    compact_table,
    num,
    pose_table,
    unknown_line,
    values_text,
    was_wrong_text,
)
from odocan.host.report.trace import PageRate, PageRates, Trace

SILENCE_S = 2.0  # nothing heard for this long: the warning line says so, and why it may be
STATUS_STALE_S = 2.0  # an ODOM_STATUS older than this: the firmware line says STALE
TOP_ROWS = 8  # header, verdict, firmware, pose (4), alert
BUS_LOAD_WARN = 0.7  # the header's bus load turns red above this (a common design limit)
WIDE_COLUMNS = 150  # from this width the trace sits beside the message table
TALL_ROWS = 40  # from this height the latest signal values are shown too



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
    lost_here: str = ""  # frames this process lost itself (``host.io.busreader.lost_here_text``)
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
    wrongs = health.get("pose_wrongs") or {}
    if wrongs.get("episodes"):  # latched: shown even when the pose is right again
        line.append(f"  {was_wrong_text(wrongs)}", style="bold reverse red")
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
    chosen = snapshot.get("robot") or {}  # the robot its PROFILE page chose (liverobot):
    if chosen.get("source") == FROM_PAGE and chosen.get("name") != DEFAULT_ROBOT:
        line.append(f"  robot {chosen.get('name')} (PROFILE page)", style="cyan")
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
    bad = {k: v for k, v in e2e.items() if k not in ("ok", *SILENCE_KEYS) and v}
    if e2e.get("silences"):  # a silence: "lost ≥ 1 (silence 20.0 s)" even with lost 0
        bad["lost"] = lost_text(e2e)
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
    if view.lost_here:
        line.append(f"  lost here: {view.lost_here}", style="bold red")
    return line
