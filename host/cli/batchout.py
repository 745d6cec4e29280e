"""``odocan analyze LOG…``'s outputs: the table of the logs' verdicts and the exit code.

A log whose verdict is UNJUDGED (``host.judge.verdictfacts``: a check judged on no sample)
counts apart from the FAILs (its row, the tally, its stderr line) and exits 1 as they do. A log
judged with an ``--integrator`` other than its firmware's FAILs for that (its stderr line),
counted out of tolerance only when its poses or checks failed too.
"""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

from odocan.host.judge.verdictfacts import verdict_name

if TYPE_CHECKING:
    from odocan.host.cli.batch import LogResult


def print_batch_summary(results: list[LogResult]) -> None:
    """One row per log: frames, verdict, largest on-board errors against the reference and
    the truth (mm, mrad); an unreadable log's row says why."""
    from rich import box
    from rich.console import Console
    from rich.table import Table

    table = Table(box=box.SIMPLE_HEAD, pad_edge=False)
    for column in ("log", "frames", "verdict", "ref mm", "ref mrad", "truth mm", "truth mrad"):
        table.add_column(column, justify="left" if column in ("log", "verdict") else "right")
    for result in results:
        if result.report is None:
            table.add_row(result.path, "-", "ERROR", "-", "-", "-", "-")
            continue
        ref = result.report["onboard_vs_reference"]
        truth = result.report.get("onboard_vs_truth") or {}
        table.add_row(
            result.path, str(result.frames), verdict_name(result.report),
            _scaled(ref.get("max_position_error_m")), _scaled(ref.get("max_heading_error_rad")),
            _scaled(truth.get("max_position_error_m")), _scaled(truth.get("max_heading_error_rad")),
        )
    longest = max(len(r.path) for r in results)  # a row per log, never wrapped or cut
    console = Console(file=sys.stdout, highlight=False, width=max(80, longest + 72))
    console.print(f"[bold]odocan analyze: {len(results)} logs[/bold]")
    console.print(table)
    for result in results:  # why a log may fail without its firmware's fault
        for hint in (result.report or {}).get("diagnosis", []):
            console.print(f"  - {result.path}: {hint}", soft_wrap=True)
    passed = sum(r.passed for r in results)
    names = [verdict_name(r.report) for r in results if r.report is not None]
    unjudged = names.count("UNJUDGED")  # said when any (verdictfacts: exit 1 as a FAIL)
    errors = sum(r.report is None for r in results)
    console.print(f"{passed} PASS, {names.count('FAIL')} FAIL, "
                  + (f"{unjudged} UNJUDGED, " if unjudged else "") + f"{errors} unreadable")


def _scaled(value: float | None) -> str:
    """metres or radians as mm or mrad (4 significant digits), ``-`` when unknown."""
    return "-" if value is None else f"{value * 1e3:.4g}"


def batch_exit(results: list[LogResult], problems: list[str]) -> int:
    """2 when a path gave nothing or a log could not be analysed, else 1 when a log failed,
    else 0; the logs at fault are named on stderr, one line each kind."""
    failed = [r.path for r in results if r.report is not None and not r.passed]
    bad = problems + [
        r.error if r.error and r.path in r.error else f"{r.path}: {r.error}"
        for r in results if r.report is None
    ]
    unjudged = [r.path for r in results if r.report is not None and not r.passed
                and verdict_name(r.report) == "UNJUDGED"]  # no pass either (verdictfacts)
    out, mismatched, given = _fail_reasons(results, unjudged)
    if out:
        print(f"FAIL: {len(out)} of {len(results)} logs out of tolerance: {', '.join(out)}",
              file=sys.stderr)
    if mismatched:
        print(f"FAIL: {len(mismatched)} of {len(results)} logs with an integrator mismatch "
              f"(--integrator {given}, not their firmware's): {', '.join(mismatched)}",
              file=sys.stderr)
    if unjudged:
        print(f"UNJUDGED: {len(unjudged)} of {len(results)} logs with a check judged on no "
              f"sample: {', '.join(unjudged)}", file=sys.stderr)
    if bad:
        print(f"error: {len(bad)} unreadable: {'; '.join(bad)}", file=sys.stderr)
        return 2
    return 1 if failed else 0


def _fail_reasons(results: list[LogResult], unjudged: list[str]
                  ) -> tuple[list[str], list[str], str]:
    """The failed logs (not ``unjudged``) by reason: out of tolerance (any failure but an
    integrator mismatch: ``passed_otherwise`` false, or no mismatch), with an integrator
    mismatch (``host.judge.diagnosis.mark_integrator``; a log with both is in both), and the
    integrator given."""
    out, mismatched, given = [], [], ""
    for r in results:
        if r.report is None or r.passed or r.path in unjudged:
            continue
        wrong = r.report.get("integrator_mismatch")
        if wrong:
            mismatched.append(r.path)
            given = str(wrong["given"])
        if not wrong or not wrong.get("passed_otherwise", False):
            out.append(r.path)
    return out, mismatched, given
