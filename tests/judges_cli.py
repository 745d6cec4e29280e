"""The CLI's judges on a log, as the fault tests call them: ``analyze`` whole and streamed, and
a tamper's FAIL by the position (a FAIL by the heading alone says nothing: a correct firmware
can FAIL by it too)."""

from __future__ import annotations

import json
from pathlib import Path

from odocan.host.cli.app import main

STREAMS = ("never", "always")


def analyze(log: Path, stream: str, report: Path | None = None) -> int:
    """``odocan analyze LOG --stream STREAM [--report REPORT]``'s exit code."""
    extra = [] if report is None else ["--report", str(report)]
    return main(["analyze", str(log), "--stream", stream, *extra])


def both_analyses(log: Path) -> list[int]:
    """analyze's exit codes, whole then streamed."""
    return [analyze(log, s) for s in STREAMS]


def fails_by_position(tampered: Path, work: Path, beyond_m: float = 5e-3) -> list[str]:
    """What is wrong with the tampered log's verdicts (nothing: ``[]``): each analysis must exit
    1 with the position beyond its allowance by more than ``beyond_m``."""
    wrong = []
    for s in STREAMS:
        code = analyze(tampered, s, work / f"{s}.json")
        vs_ref = json.loads((work / f"{s}.json").read_text())["onboard_vs_reference"]
        beyond = vs_ref["max_position_error_beyond_allowance_m"]
        if code != 1 or beyond <= beyond_m:
            wrong.append(f"--stream {s}: exit {code}, position {beyond * 1e3:.4g} mm beyond")
    return wrong
