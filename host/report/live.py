"""Rendering of the monitor's model with rich: the plain screen of ``odocan monitor`` (``render``)
and the MQTT fleet table (``render_fleet``), plus the pieces the TUI (``host.report.tui``) lays
out: the firmware line, the pose table, the message table, the "not checked" line.

Every function here is a pure function of a snapshot (``host.judge.monitor.BusMonitor.snapshot``
or ``fleet_snapshot``) and of times passed in, so the same call draws the terminal, a test's
fixed-size console and a recorded SVG.
"""

from __future__ import annotations

import math
import time
from typing import Any

from rich import box
from rich.console import Group, RenderableType
from rich.table import Table
from rich.text import Text

from odocan.host.jsonutil import real
from odocan.host.judge.sources import FIRMWARE_NODE
from odocan.host.protocol.e2e import E2E_KEYS
from odocan.host.protocol.e2e_silence import lost_text, silence_caption

STALE_S = 1.0  # a message not heard for this long is shown dimmed
FLEET_STALE_S = 3.0  # a robot whose last MQTT message is older than this is marked stale


def render(snapshot: dict[str, Any], *, source: str,
           heard: dict[str, float] | None = None) -> RenderableType:
    """The live screen (fits 80 columns): header, per-message statistics, latest signal values,
    firmware status, pose comparison, frames not checked.

    ``heard``: message name -> seconds since last heard (rows not heard for ``STALE_S`` dimmed).
    """
    header = Text.assemble(
        ("odocan monitor ", "bold"), (source, "cyan"),
        f"   {snapshot['duration_s']:.1f} s   {snapshot['frames_total']} frames   Ctrl-C quits",
    )
    heard = heard or {}
    return Group(
        header, messages_table(snapshot, heard), signals_table(snapshot, heard),
        status_line(snapshot.get("status")), health_line(snapshot.get("health")),
        pose_table(snapshot), pose_note(snapshot),
        unknown_line(snapshot["unknown"]),
    )


def compact_table(*columns: str) -> Table:
    """A compact table; the first column left-aligned, the others right-aligned."""
    table = Table(box=box.SIMPLE_HEAD, header_style="bold", pad_edge=False, show_edge=False,
                  padding=(0, 1, 0, 0))
    for i, column in enumerate(columns):
        table.add_column(column, justify="left" if i == 0 else "right", no_wrap=True)
    return table


def messages_table(snapshot: dict[str, Any], heard: dict[str, float]) -> Table:
    table = compact_table("message", "ID", "frames", "Hz", "jitter ms", "E2E ok", "lost", "rep",
                   "crc", "seq")
    for name, m in snapshot["messages"].items():
        e2e = m["e2e"]
        dim = "dim" if m.get("stale") or heard.get(name, 0.0) > STALE_S else None
        table.add_row(
            name, m["id"], str(m["count"]), num(m["rate_hz"], ".1f"),
            num(m["jitter_ms"], ".2f"),
            *(lost_text(e2e, cell=True) if k == "lost" and e2e else num(e2e.get(k), "d")
              for k in E2E_KEYS),
            style=dim,
        )
        for page, stats in m.get("pages", {}).items():
            table.add_row(f"  {page}", "", str(stats["count"]), num(stats["rate_hz"], ".1f"),
                          num(stats["jitter_ms"], ".2f"), *("" for _ in E2E_KEYS), style=dim)
    table.caption = silence_caption({n: m["e2e"] for n, m in snapshot["messages"].items()})
    table.caption_justify = "left"
    return table


def signals_table(snapshot: dict[str, Any], heard: dict[str, float]) -> Table:
    table = Table(box=box.SIMPLE_HEAD, header_style="bold", pad_edge=False, show_edge=False)
    table.add_column("message", no_wrap=True)
    table.add_column("latest values", overflow="fold", ratio=1)
    for name, m in snapshot["messages"].items():
        table.add_row(name, values_text(m.get("last_frame", m["last"]), m["units"]),
                      style="dim" if heard.get(name, 0.0) > STALE_S else None)
    return table


def values_text(last: dict[str, Any], units: dict[str, str]) -> str:
    items = []
    for name, value in last.items():
        text = f"{value:.4f}".rstrip("0").rstrip(".") if isinstance(value, float) else str(value)
        unit = units.get(name, "")
        items.append(f"{name} {text}{' ' + unit if unit else ''}")
    return ", ".join(items)


def status_line(status: dict[str, Any] | None) -> Text:
    if not status:
        return Text("firmware: no ODOM_STATUS summary yet", style="dim")
    state = str(status.get("state"))
    colour = {"OK": "green", "DEGRADED": "yellow", "FAULT": "bold red"}.get(state, "")
    errors = ", ".join(status.get("errors") or []) or "none"
    totals = ", ".join(f"{k.removesuffix('_frames')} {v}" for k, v in status.items()
                       if k.endswith("_frames"))
    return Text.assemble(
        ("firmware ", "bold"), (state, colour),
        f"   integrator {status.get('integrator')}   errors 0x{status.get('error_mask', 0):04X}"
        f" ({errors})   uptime {status.get('uptime_s')} s"
        + (f"   frames {totals}" if totals else ""),
    )


BAD_VERDICTS = frozenset({"STALE", "CONFLICT", "POSE WRONG", "DISTANCE WRONG", "TWIST WRONG",
                          "FAULT", "NO FIRMWARE"})


def health_line(health: dict[str, Any] | None) -> Text:
    """The monitor's verdict, why, the firmware's age and the latest event."""
    if not health:
        return Text("")
    state = str(health["state"])
    colour = "green" if state == "OK" else "bold red" if state in BAD_VERDICTS else "yellow"
    firmware = health["nodes"].get(FIRMWARE_NODE)
    age = f"   age {firmware['age_s']:.2f} s" if firmware else ""
    why = f": {'; '.join(health['why'])}" if health["why"] else ""
    events = health["events"]
    last = f"   event: {events[-1]['kind']} ({events[-1]['detail']})" if events else ""
    wrongs = health.get("pose_wrongs") or {}
    was = f"  {was_wrong_text(wrongs)}" if wrongs.get("episodes") else ""
    return Text.assemble(("verdict ", "bold"), (state, colour), (was, "bold red"),
                         why + age + last)


def was_wrong_text(wrongs: dict[str, Any]) -> str:
    """The POSE WRONG episodes latched (``health.pose_wrongs``), short for 80 columns:
    ``WAS WRONG 2x, worst 2.05 mm 0.048 mrad at 3.0 s``."""
    worst = wrongs["worst"]
    return (f"WAS WRONG {wrongs['episodes']}x, worst {worst['dpos_mm']:.3g} mm "
            f"{worst['dheading_mrad']:.3g} mrad at {worst['t_s']:.1f} s")


def pose_table(snapshot: dict[str, Any], *, decimals: int = 4) -> Table:
    """On-board, reference and truth poses (headings in (-pi, pi], as the model gives them);
    on-board minus each in mm and mrad with ``decimals`` places (latest and max)."""
    table = compact_table("pose", "x m", "y m", "hdg rad", "Δ mm", "Δ mrad", "max mm", "max mrad")
    errors = snapshot["error"]
    rows = (("on-board", snapshot["pose"], None),
            ("reference", snapshot["reference"], errors["pose_vs_reference"]),
            ("truth", snapshot["truth"], errors["pose_vs_truth"]))
    for label, pose, error in rows:
        pose, error = pose or {}, error or {}
        milli = [scaled(error.get(key), decimals)
                 for key in ("dpos_m", "dheading_rad", "max_dpos_m", "max_dheading_rad")]
        table.add_row(label, num(pose.get("x_m"), ".4f"), num(pose.get("y_m"), ".4f"),
                      num(pose.get("heading_rad"), ".4f"), *milli)
    return table


def pose_note(snapshot: dict[str, Any]) -> Text:
    ref, errors = snapshot["reference"], snapshot["error"]
    samples = [(errors[key] or {}).get("samples", 0) for key in ("pose_vs_reference",
                                                                  "pose_vs_truth")]
    return Text(f"Δ: on-board minus the row; reference {ref.get('integrator') or '(integrator?)'}"
                f", started {ref.get('starts', 0)}x; compared {samples[0]} poses, {samples[1]} "
                "truth", style="dim")


def unknown_line(unknown: dict[str, Any]) -> Text:
    counts = {k: v for k, v in unknown.items() if k != "ids" and v}
    if not counts:
        return Text("not checked: none", style="dim")
    text = ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in counts.items())
    ids = ", ".join(f"{k}×{v}" for k, v in list(unknown.get("ids", {}).items())[:8])
    return Text(f"not checked: {text}" + (f" (IDs {ids})" if ids else ""), style="yellow")


def num(value: Any, spec: str) -> str:
    """``value`` formatted with ``spec``, or ``-`` when it is not a finite number."""
    number = real(value)
    return "-" if number is None else format(value if isinstance(value, int) else number, spec)


def scaled(value: Any, decimals: int = 4) -> str:
    """Metres as mm, radians as mrad (``-`` when not a finite number)."""
    number = real(value)
    return "-" if number is None else f"{number * 1e3:.{decimals}f}"


# --- the MQTT fleet -------------------------------------------------------------------------


def render_fleet(snapshot: dict[str, Any], *, source: str, elapsed_s: float, note: str = "",
                 now_unix_s: float | None = None,
                 stale_after_s: float = FLEET_STALE_S) -> RenderableType:
    """The fleet table of ``odocan monitor --mqtt``, worst robot first.

    Rows are sorted by position error against the reference (largest first, robots without one
    last, then by name), those whose pose the bridge judged wrong first (``pose_wrong``: the
    latest sample, one since the previous ``error``, or an offset standing in the pose's life;
    their state POSE WRONG where the firmware says OK or DEGRADED). A robot whose latest
    message (``updated_unix_s``) is older than ``stale_after_s`` at ``now_unix_s`` (default:
    now) is shown ``stale`` with the age, dimmed, whatever its retained status says; an offline
    robot is ``offline``.
    """
    now_unix_s = time.time() if now_unix_s is None else now_unix_s
    rows = sorted(snapshot.items(), key=_worst_first)
    stale = sum(1 for _, row in rows if fleet_age_s(row, now_unix_s) > stale_after_s)
    header = Text.assemble(  # one line: the broker's URL last, cut short when it does not fit
        ("odocan monitor --mqtt ", "bold"),
        f"{len(snapshot)} robots" + (f" ({stale} stale)" if stale else "")
        + f"   {elapsed_s:.1f} s   Ctrl-C quits   ", (source, "cyan"),
        no_wrap=True, overflow="ellipsis",
    )
    table = fleet_table()
    for name, row in rows:
        age_s = fleet_age_s(row, now_unix_s)
        pose, error, status = row["pose"] or {}, row["error"] or {}, row["status"] or {}
        state = str(status.get("state", "-"))
        if row.get("pose_wrong") is True and state in ("OK", "DEGRADED", "-"):
            state = "POSE WRONG"  # as the monitor's verdict: the bridge's judgement outranks
        if not row["online"]:
            state = "offline"
        elif age_s > stale_after_s:  # infinite: only retained messages, never heard live
            state = f"stale {age_s:.0f}s" if math.isfinite(age_s) else "stale"
        table.add_row(
            name, num(pose.get("x_m"), ".4f"), num(pose.get("y_m"), ".4f"),
            num(pose.get("heading_rad"), ".4f"), scaled(error.get("dpos_m")),
            scaled(error.get("dheading_rad")), state,
            " ".join(status.get("errors") or []) or "-", num(row["rate_hz"], ".1f"),
            style=None if row["online"] and age_s <= stale_after_s else "dim",
        )
    parts: list[RenderableType] = [header, table]
    if note:
        parts.append(Text(note, style="yellow"))
    return Group(*parts)


def fleet_table() -> Table:
    """The empty fleet table (columns of ``render_fleet``)."""
    out = compact_table("robot", "x m", "y m", "hdg rad", "Δ mm", "Δ mrad", "state", "errors",
                        "fr/s")
    for column in out.columns[6:8]:
        column.justify = "left"
    out.columns[7].no_wrap, out.columns[7].min_width = False, 8  # names wrap at spaces
    return out


def fleet_age_s(row: dict[str, Any], now_unix_s: float) -> float:
    """Seconds since a fleet row was last updated (infinite when never)."""
    updated = row.get("updated_unix_s") or 0.0
    return now_unix_s - updated if updated > 0 else math.inf


def with_staleness(snapshot: dict[str, Any], now_unix_s: float,
                   stale_after_s: float = FLEET_STALE_S) -> dict[str, Any]:
    """``snapshot``'s rows with what the screen shows of their age: ``age_s`` (s since the
    robot's last message, None when never) and ``stale`` (older than ``stale_after_s``)."""
    out = {}
    for name, row in snapshot.items():
        age_s = fleet_age_s(row, now_unix_s)
        finite = math.isfinite(age_s)
        out[name] = {**row, "age_s": round(age_s, 3) if finite else None,
                     "stale": not finite or age_s > stale_after_s}
    return out


def _worst_first(item: tuple[str, dict[str, Any]]) -> tuple[bool, int, float, str]:
    name, row = item
    error = row.get("error")
    dpos_m = real(error.get("dpos_m")) if isinstance(error, dict) else None
    right = row.get("pose_wrong") is not True
    if dpos_m is None:
        return (right, 1, 0.0, name)
    return (right, 0, -dpos_m, name)
