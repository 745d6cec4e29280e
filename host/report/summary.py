"""What ``odocan run``, ``analyze`` and ``replay`` share after the analysis: options and outputs.

* ``add_check_arguments(parser)`` adds ``--tolerance``, ``--report`` and ``--plot``;
  ``check_output_paths(args)`` refuses a bad ``--plot``/``--report`` path *before* a long run.
* ``finish(analysis, args, title=...)`` writes the JSON report and the plot, prints the summary
  table (rich, to stdout) and returns the exit code: 0 when the on-board pose is within tolerance
  of the float64 reference, 1 when it is not.

``--tolerance`` is either one number, the position tolerance in metres (the heading keeps its
default of one LSB of the pose signal, 2*pi/65536 rad), or ``pos=METRES,heading=RADIANS`` (any
subset, any order). The default, ``pos=1e-4,heading=9.587e-5``, is one LSB of ``ODOM_POSE_X/Y``.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from odocan.host.jsonutil import write_report
from odocan.host.judge import namesahead, verdictfacts
from odocan.host.judge.analysis import Analysis, Tolerance
from odocan.host.judge.finalstate import final_text
from odocan.host.judge.samples import POSITION_LSB_M
from odocan.host.outputs import OutputError, check_writable, replaced
from odocan.host.protocol.e2e_silence import lost_text, silence_caption
from odocan.host.report.failedchecks import first_pose_failures, twist_failures
from odocan.host.report.judgedfacts import judged_fact, placed_fact
from odocan.host.report.logtime import origin_s, start_text
from odocan.host.stopped import mark_stopped, partial_verdict, stopped_text
from odocan.sim.exceptions import ConfigurationError

COARSE_KEPT_LSB = 2  # an APPLY's check wider than this cannot tell a jump of 2 LSB: said

if TYPE_CHECKING:  # rich is imported where a summary is printed, not by the options above
    from rich.console import Console
    from rich.table import Table

PLOT_SUFFIXES = (".png", ".svg")
_E2E_COLUMNS = {
    "ok": "E2E ok",
    "lost": "lost",
    "repeated": "repeated",
    "crc_errors": "CRC err",
    "wrong_sequence": "wrong seq",
}
_TOLERANCE_KEYS = {"pos": "position_m", "heading": "heading_rad"}


def parse_tolerance(text: str) -> Tolerance:
    """``"1e-4"`` (position, metres) or ``"pos=1e-4,heading=1e-4"``; argparse type function."""
    values: dict[str, float] = {}
    items = [item.strip() for item in text.split(",") if item.strip()]
    if len(items) == 1 and "=" not in items[0]:
        items = [f"pos={items[0]}"]
    for item in items:
        key, sep, raw = (part.strip() for part in item.partition("="))
        if not sep or key not in _TOLERANCE_KEYS:
            raise argparse.ArgumentTypeError(
                f"expected METRES or pos=METRES,heading=RADIANS, got {text!r}"
            )
        try:
            value = float(raw)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and value > 0):
            raise argparse.ArgumentTypeError(f"{key}={raw!r} must be a positive number")
        values[_TOLERANCE_KEYS[key]] = value
    if not values:
        raise argparse.ArgumentTypeError("empty tolerance")
    return Tolerance(**values)


def add_check_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--tolerance``, ``--report`` and ``--plot`` to ``parser``."""
    group = parser.add_argument_group("check and outputs")
    group.add_argument(
        "--tolerance",
        type=parse_tolerance,
        default=Tolerance(),
        metavar="SPEC",
        help="on-board vs reference tolerance: METRES, or pos=METRES,heading=RADIANS "
        "(default: one LSB of the pose signals, pos=1e-4,heading=9.587e-5)",
    )
    group.add_argument("--report", type=Path, metavar="PATH", help="write the JSON report here"
                       " (- for stdout: the summary then goes to stderr)")
    group.add_argument(
        "--plot", type=Path, metavar="PATH", help="write the trajectory and error plot (.png, .svg)"
    )


def check_output_paths(args: argparse.Namespace) -> None:
    """Refuse a ``--plot`` of unknown format or an output that cannot be written, up front."""
    plot: Path | None = args.plot
    if plot is not None and plot.suffix.lower() not in PLOT_SUFFIXES:
        raise ConfigurationError(
            f"--plot {plot}: unknown format {plot.suffix or '(none)'!r} (use .png or .svg)"
        )
    for option, path in (("--plot", plot), ("--report", args.report)):
        check_writable(path, option)


def finish(analysis: Analysis, args: argparse.Namespace, *, title: str) -> int:
    """Print the summary, then write ``--plot`` and ``--report``; 0 when passed, 1 when not.

    The summary comes first so that an output that cannot be written (an ``OutputError``
    naming its path, exit 2) never loses the verdict. The report comes last, so that it can
    say that the plot failed (``output_failed``, ``passed`` false: the command exits 2, as for a
    failed ``--log`` recording, ``as_written``): a CI step reading it must not see a PASS the
    command did not give (with ``ulimit -f`` the plot failed after the report said PASS)."""
    from rich.console import Console

    console = Console(file=sys.stdout, highlight=False)
    verdictfacts.mark(analysis.report)  # a check on 0 samples, a stuck E2E COUNTER: no PASS
    analysis.passed = mark_stopped(analysis.report)
    print_summary(analysis.report, args.tolerance, console, title=title)
    sys.stdout.flush()
    failed = None
    if args.plot is not None:
        from odocan.host.report.plots import plot_analysis  # matplotlib only when asked

        try:
            with replaced(args.plot, "--plot") as target:  # a full disk: an older plot kept
                plot_analysis(analysis, target, tolerance=args.tolerance)
        except OutputError as exc:
            failed = exc
    if args.report is not None:
        report = as_written(analysis.report)
        write_report(args.report, report if failed is None else {
            **report, "passed": False, "output_failed": str(failed)})
    if failed is not None:
        raise failed
    return 0 if analysis.passed else 1


def as_written(report: dict[str, Any]) -> dict[str, Any]:
    """The JSON report of ``report``: no pass when its ``--log`` recording failed (``recording``:
    the command exits 2, the log holds part of the run), though the summary printed its poses'
    verdict (the firmware is not to blame for a full disk)."""
    if report.get("recording") is None:
        return report
    return {**report, "passed": False}


def print_summary(
    report: dict[str, Any], tolerance: Tolerance, console: Console, *, title: str
) -> None:
    """The run in a few lines, the comparison table and the verdict (fits 80 columns)."""
    from rich.padding import Padding

    console.print(f"[bold]{title}[/bold]", soft_wrap=True)
    for label, text in _facts(report):
        console.print(f"  {label:<10} {text}", soft_wrap=True, highlight=False)
    tables = [frames_table(report), comparison_table(report)]
    bus = report.get("bus")
    if bus:
        console.print()
        for i, line in enumerate(bus_lines(bus)):
            console.print(f"  {'bus' if i == 0 else '':<10} {line}", soft_wrap=True)
        if bus.get("messages"):
            tables.insert(1, bus_table(bus))
    for table in tables:
        console.print()
        console.print(Padding(table, (0, 0, 0, 2), expand=False))
    console.print()
    stuck, unjudged = verdictfacts.reasons_of(report)
    passed = _judged_verdict(report)  # a signal's stop: what ran, said as partial
    verdict, style = ("PASS", "green") if passed else ("FAIL", "bold red")
    if passed and unjudged:  # what was judged passed, a check judged nothing: no PASS
        verdict, style = "UNJUDGED", "bold yellow"
    if passed and (report.get("replay") or {}).get("passed") is False:  # its FAIL follows
        verdict, style = "met", "bold"
    if report.get("stopped"):  # a signal ended it early: never a plain PASS
        verdict = f"{stopped_text(report['stopped'])}: partial drive {verdict}"
        style = "bold yellow" if passed else style
    twist = report.get("onboard_twist_vs_reference") or {"passed": True}
    pose_met = _pose_within(report, tolerance)
    distance = report.get("onboard_distance_vs_reference") or {"passed": True}
    verdict, style = _own_lines(report, console, (verdict, style), pose_met and twist["passed"],
                                pose_met and twist["passed"] and distance["passed"])
    stuck = [*namesahead.detail(report), *stuck]  # a pose naming a frame not yet sent first
    line = "; ".join([*stuck, *unjudged, _criteria_line(report, tolerance, pose_met, bool(stuck)),
                      *kept_unjudged(report)])
    console.print(f"[{style}]{verdict}[/{style}]: {line}", soft_wrap=True)


def _criteria_line(report: dict[str, Any], tolerance: Tolerance, pose_met: bool,
                   stuck: bool) -> str:
    """The pose and ODOM_TWIST criteria in words, what failed first (``stuck``: E2E REPEATED)."""
    twist = report.get("onboard_twist_vs_reference") or {"passed": True}
    distance = report.get("onboard_distance_vs_reference") or {"passed": True}
    pose = (
        f"on-board vs reference within "
        f"{tolerance.position_m * 1e3:.4g} mm and {tolerance.heading_rad * 1e3:.4g} mrad"
        + (f" (plus {allowance * 1e3:.4g} mm for encoder frames the firmware lost)"
           if (allowance := report["onboard_vs_reference"].get("loss_allowance_m")) else "")
        + (f" (plus {twins * 1e3:.4g} mm for encoder frames with a twin)"
           if (twins := (report.get("reference_breaks") or {}).get("twin_allowance_m")) else "")
    )
    failed = twist_failures(twist, distance) + first_pose_failures(report)
    if pose_met and failed:  # name what failed first: the pose did not
        line = "; ".join(failed) + f" (the pose criterion is met: {pose})"
    else:
        line = "; ".join([pose + ("" if pose_met else ": not met"), *failed])
    if stuck and pose_met:
        accepted = (report.get("samples") or {}).get("onboard")
        line = f"the pose criterion is met on the {accepted} poses accepted: {line}"
    return line


def _judged_verdict(report: dict[str, Any]) -> bool:
    """What was judged (``partial_verdict``): a stuck E2E COUNTER fails, a check on 0 not."""
    unjudged = report.get("unjudged")
    if not unjudged:
        return partial_verdict(report)
    stopped = report.get("stopped") or {}
    return bool(stopped.get("partial_passed", unjudged["judged_passed"])
                and unjudged["judged_passed"] and not report.get("e2e_not_advancing"))


def _own_lines(report: dict[str, Any], console: Console, said: tuple[str, str], met: bool,
               all_met: bool) -> tuple[str, str]:
    """The verdicts of their own before the pose line (a set-pose that moved what it kept, two
    sources on one ID, too few poses judged), printed; the pose line's word and style after
    them (``said``: before them; ``met``: the pose and twist criteria are; ``all_met``: the
    distance too)."""
    verdict, style = said
    for kept in kept_failures(report):  # a set-pose that moved what it kept: a FAIL of its own
        console.print(f"[{style}]{verdict}[/{style}]: {kept}", soft_wrap=True)
        verdict, style = "otherwise", "bold" if met else style
    conflict = report.get("two_sources")
    if conflict:  # a FAIL of its own; the pose before it is judged as usual
        console.print(f"[{style}]{verdict}[/{style}]: {conflict['detail']} "
                      f"({conflict['frames_not_judged']} frames from there not judged)",
                      soft_wrap=True)
        verdict, style = "before it", "bold" if met else style
    wrong = report.get("integrator_mismatch")
    if wrong:  # --integrator other than the firmware's (host.judge.diagnosis): a FAIL of its own
        console.print(f"[{style}]{verdict}[/{style}]: {wrong['detail']}", soft_wrap=True)
        verdict, style = "otherwise", "bold" if met else style
    floor = report.get("judged_floor")
    if floor:  # too few poses judged (judgedfloor): UNJUDGED when nothing else failed
        word = "UNJUDGED" if all_met and verdict == "FAIL" else verdict
        console.print(f"[{style}]{word}[/{style}]: {floor['detail']}", soft_wrap=True)
        verdict, style = "otherwise", "bold" if met else style
    return verdict, style


def kept_unjudged(report: dict[str, Any]) -> list[str]:
    """The set-poses whose check of what their APPLY kept could not be made, or only with a
    bound over ``COARSE_KEPT_LSB`` (merged steps before it: a stall's, a gap's), in words: the
    verdict says so, never a silent PASS (a jump within them is judged by the life's fit
    alone, which cannot see a jump at its start); likewise a power-up whose first pose a stall
    left unjudged (``host.judge.stallpowerup``)."""
    said, first_s = [], origin_s(report)
    for event in report.get("events") or []:
        kept = event.get("kept")
        if event.get("kind") == "power_up_unproven":  # its first pose (stallpowerup)
            said.append(f"the first pose at {event['t_s'] - first_s:.3f} s not judged "
                        f"({event['detail']})")
        if event.get("kind") == "unjudged":  # a life without samples (silentlives)
            said.append(event["detail"].split(": ", 1)[0])
        if event.get("kind") != "set_pose":
            continue
        at = f"what the ODOM_SET_POSE APPLY at {event['t_s'] - first_s:.3f} s kept"
        if event.get("kept_not_judged"):
            said.append(f"{at} not judged ({event['kept_not_judged']})")
        elif isinstance(kept, dict) and kept["passed"] and \
                kept["bound_m"] > COARSE_KEPT_LSB * POSITION_LSB_M:
            why = ("the frames the firmware may have integrated around its re-prime"
                   if kept.get("reprimed") else "the merged steps before it")
            said.append(f"{at} judged only within {kept['bound_m'] * 1e3:.4g} mm ({why})")
    return said


def kept_failures(report: dict[str, Any]) -> list[str]:
    """The set-poses whose APPLY moved a field it kept (``host.judge.setposekept``), in words."""
    first_s = origin_s(report)
    return [f"at {event['t_s'] - first_s:.3f} s the firmware's pose jumped "
            f"{event['kept']['position_jump_m'] * 1e3:.4g} mm and "
            f"{event['kept']['heading_jump_rad'] * 1e3:.4g} mrad at an ODOM_SET_POSE APPLY that "
            f"kept {', '.join(event['kept']['fields_kept'])} (nothing staged for them in this "
            "firmware life)"
            for event in report.get("events") or []
            if event.get("kind") == "set_pose" and isinstance(event.get("kept"), dict)
            and not event["kept"]["passed"]]


def _pose_within(report: dict[str, Any], tolerance: Tolerance) -> bool:
    vs_ref = report["onboard_vs_reference"]
    position = vs_ref.get("max_position_error_beyond_allowance_m", vs_ref["max_position_error_m"])
    return bool(
        position <= tolerance.position_m
        and vs_ref["max_heading_error_rad"] <= tolerance.heading_rad
    )


_START_TEXT = {  # the reference's start (host.judge.powerup, reference_path, setposes)
    "power-up": "exact from power-up: (0, 0, 0) at the frame the firmware primed on",
    "fitted": "fitted to the samples (no power-up in the log: a start offset cannot be told)",
    "set pose": "exact from the set-pose applied",
}


def _facts(report: dict[str, Any]) -> list[tuple[str, str]]:
    """(label, text) lines: robot, geometry, run, time, the reference's start, distance, frames
    not checked, pose."""
    robot = report["robot"]
    pose = report["final_onboard_pose"]
    truth = report.get("onboard_vs_truth") or {}
    first_s = origin_s(report)  # the times said count from the log's first frame (logtime)
    facts = [
        (
            "robot",
            f"{robot['name']}, {robot['counts_per_rev']} counts/rev, "
            f"{robot['counter_bits']}-bit counters",
        ),
        (
            "geometry",
            f"wheel radii {robot['wheel_radius_left_m']:g}/"
            f"{robot['wheel_radius_right_m']:g} m, wheelbase {robot['wheelbase_m']:g} m",
        ),
        (
            "run",
            f"integrator {report['integrator']}, scenario {report.get('scenario') or '-'}, "
            f"seed {_or_dash(report.get('seed'))}",
        ),
        ("time", _time_text(report)),
    ]
    if start := start_text(report):
        facts.append(("log", start))
    inputs = report.get("inputs") or {}
    if inputs.get("errors") or inputs.get("faults"):  # what the run injected (a log: unknown)
        facts.append(("injected", f"errors {inputs.get('errors') or 'none'}, "
                                  f"faults {inputs.get('faults') or 'none'}"))
    if report.get("reference_start"):
        facts.append(("start", _START_TEXT.get(report["reference_start"],
                                               str(report["reference_start"]))))
    facts.extend(fact for fact in (placed_fact(report), judged_fact(report)) if fact)
    if truth.get("distance_travelled_m") is not None:
        facts.append(("distance", f"{truth['distance_travelled_m']:.3f} m travelled"))
    reboots = report.get("reboots") or []
    if reboots:  # each restarts the reference (host.judge.reboots)
        facts.append(("reboots", f"{len(reboots)}: the firmware restarted at "
                      + ", ".join(f"{r['t_s'] - first_s:.2f} s ({r['reference_start']})"
                                  for r in reboots)
                      + "; the reference restarted with it"))
    stalls = [e for e in report.get("events") or [] if e.get("kind") == "firmware_stall"]
    if stalls:  # the reference placed again after each (host.judge.analysis, reference_breaks)
        facts.append(("stalls", f"{len(stalls)}: the firmware went silent or held its pose from "
                      + ", ".join(f"{e['t_s'] - first_s:.2f} s" for e in stalls[:5])
                      + (", ..." if len(stalls) > 5 else "")
                      + "; the reference placed again after each, within its merge bound"))
    reprimed = [e for e in report.get("events") or [] if e.get("kind") == "counter_restart"]
    if reprimed:  # the truth row is off by the motion there (reference_path, ambiguity)
        facts.append(("re-primed", f"{len(reprimed)}: the reference re-primed where the firmware "
                      "must (COUNTER_RESET) at "
                      + ", ".join(f"{e['t_s'] - first_s:.2f} s" for e in reprimed[:5])
                      + (", ..." if len(reprimed) > 5 else "")
                      + "; the motion across is unknowable: the truth row is off by it, and a "
                        "firmware that integrated it instead is off the reference"))
    unchecked = {k: v for k, v in (report.get("unknown_frames") or {}).items() if v}
    if unchecked:
        facts.append(
            (
                "unchecked",
                f"{sum(unchecked.values())} frames: "
                + ", ".join(f"{k} {v}" for k, v in unchecked.items()),
            )
        )
    facts.append(
        (
            "final pose",
            f"x {pose['x_m']:.4f} m, y {pose['y_m']:.4f} m, heading "
            f"{pose['heading_rad']:.4f} rad ({math.degrees(pose['heading_rad']):.2f} deg)",
        )
    )
    final = final_text(report.get("firmware_final"), first_s)
    if final:  # a PASS may end DEGRADED (a latched REASON): said, never a plain PASS
        facts.append(("firmware", final))
    return facts


def frames_table(report: dict[str, Any]) -> Table:
    """Frames per message and their E2E check counts (a dash where a message has none)."""
    table = _table()
    table.add_column("message")
    for column in ("frames", *_E2E_COLUMNS.values()):
        table.add_column(column, justify="right")
    frames: dict[str, int] = report.get("frames", {})
    e2e: dict[str, dict[str, Any]] = report.get("e2e", {})
    for name, count in frames.items():
        counts = e2e.get(name, {})
        table.add_row(name, str(count), *(lost_text(counts, cell=True) if key == "lost" and counts
                                          else _or_dash(counts.get(key)) for key in _E2E_COLUMNS))
    table.caption, table.caption_justify = silence_caption(e2e), "left"
    table.add_row("total", str(sum(frames.values())), *("" for _ in _E2E_COLUMNS), style="bold")
    return table


def bus_lines(section: dict[str, Any]) -> list[str]:
    """The bus section in a few lines: bitrate, measured load, any latency above its bound."""
    load = section.get("load")
    load_text = "-" if load is None else f"{load:.1%}"
    lines = [
        f"{section['bitrate'] // 1000} kbit/s, measured load {load_text} over "
        f"{section['span_s']:.2f} s, {section['frames']} frames ({section['source']})"
    ]
    if section.get("analysis_note"):
        lines.append(f"no worst-case bounds: {section['analysis_note']}")
    over = [m["name"] for m in section.get("messages", []) if m["within_bound"] is False]
    if over:
        lines.append("measured latency ABOVE the analysis' bound R: " + ", ".join(over))
    starved = [
        f"{m['name']} ({m['late']} late, {m['still_queued']} never sent)"
        for m in section.get("messages", [])
        if m.get("starved")
    ]
    if starved:
        lines.append("STARVED past their deadline: " + ", ".join(starved))
    return lines


def bus_table(section: dict[str, Any]) -> Table:
    """Per message: frames, measured max and p99 latency (queued to end of frame), the
    analysis' worst-case R and the deadline D, in ms; frames past D, frames never sent."""
    table = _table()
    table.add_column("message")
    for column in ("frames", "max ms", "p99 ms", "R ms", "D ms", "late", "queued"):
        table.add_column(column, justify="right")
    for row in section["messages"]:
        style = "bold red" if row["within_bound"] is False or row.get("starved") else None
        table.add_row(
            row["name"], str(row["frames"]), _ms_of_us(row["max_latency_us"]),
            _ms_of_us(row["p99_latency_us"]), _ms_of_us(row["bound_us"]),
            _ms_of_us(row["deadline_us"]), str(row.get("late", 0)),
            str(row.get("still_queued", 0)), style=style,
        )
    return table


def _ms_of_us(value_us: float | None) -> str:
    return "-" if value_us is None else f"{value_us / 1000:.3f}"


def _time_text(report: dict[str, Any]) -> str:
    text = f"{report['sim_seconds']:.2f} s simulated"
    if report.get("wall_seconds") is not None:
        text += f" in {report['wall_seconds']:.2f} s"
    if report.get("realtime_factor") is not None:
        text += f" ({report['realtime_factor']:.0f}x real time)"
    return text


def comparison_table(report: dict[str, Any]) -> Table:
    """Max and final position/heading errors of the on-board pose, vs reference and vs truth."""
    table = _table()
    table.add_column("on-board vs")
    for column in ("max position", "final position", "max heading", "final heading"):
        table.add_column(column, justify="right")
    rows = (("reference", "onboard_vs_reference"), ("truth", "onboard_vs_truth"))
    for label, key in rows:
        errors = report.get(key) or {}
        table.add_row(
            label,
            _mm(errors.get("max_position_error_m")),
            _mm(errors.get("final_position_error_m")),
            _mrad(errors.get("max_heading_error_rad")),
            _mrad(errors.get("final_heading_error_rad")),
        )
    return table


def _mm(value: float | None) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value * 1e3:.4f} mm"


def _mrad(value: float | None) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value * 1e3:.4f} mrad"


def _or_dash(value: object) -> str:
    return "-" if value is None else str(value)


def _table() -> Table:
    """An empty summary table: a rule under the bold header, no outer edge."""
    from rich import box
    from rich.table import Table

    return Table(box=box.SIMPLE_HEAD, header_style="bold", pad_edge=False, show_edge=False)
