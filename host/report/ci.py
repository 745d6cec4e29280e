"""``--junit PATH`` for every command that judges: the checks of a report, as JUnit testcases.

* ``add_junit_argument(parser)`` adds the option; ``check_junit_path(args)`` refuses a path that
  cannot be written before the work starts; ``write_checks(args, suite, checks)`` writes it.
* ``analysis_checks(report)``: the two checks behind ``run``/``analyze``/``replay``'s verdict
  (on-board vs float64 reference, position and heading, against the tolerance), plus the
  replay's own comparison with the logged firmware when the report has it, each set-pose
  APPLY's check of the fields it kept (``set_pose_kept``), a failed
  ``completed`` when a signal stopped the command before it finished (``host.stopped``), and a
  failed ``recording`` when a write error (a full disk) stopped ``--log``.
* ``umbmark_checks``/``calibration_checks``/``experiment_checks``: the figures of the benchmark
  and, when the report carries a verdict (``passed``, ``faults``), a ``verdict`` testcase that
  fails with its reasons.

A failed testcase carries the measured figure and its limit, so a CI page shows both.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from odocan.host.judge import namesahead, verdictfacts
from odocan.host.outputs import check_writable, write_text
from odocan.host.report.junit import Check, junit_xml
from odocan.host.stopped import stopped_text


def add_junit_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``--junit PATH``."""
    parser.add_argument(
        "--junit", type=Path, metavar="PATH",
        help="write the checks as JUnit XML for CI (one testcase per check;"
        " - for stdout: the summary then goes to stderr)",
    )


def check_junit_path(args: argparse.Namespace) -> None:
    """Refuse a ``--junit`` that cannot be written, up front."""
    check_writable(getattr(args, "junit", None), "--junit")


def write_checks(args: argparse.Namespace, suite: str, checks: list[Check],
                 properties: dict[str, str] | None = None) -> None:
    """Write ``checks`` to ``--junit`` (nothing without it), with the suite's ``properties``
    (what it was judged with, e.g. the robot and where it came from); an I/O error names the
    path."""
    path: Path | None = getattr(args, "junit", None)
    if path is not None:
        write_text(path, junit_xml(suite, checks, properties=properties), "--junit")


def analysis_checks(report: dict[str, Any]) -> list[Check]:
    """On-board vs reference, position and heading; the replay's comparison when present."""
    ref = report.get("onboard_vs_reference") or {}
    tol = report["tolerance"]
    checks = [
        _within("onboard_vs_reference_position", ref.get("max_position_error_m"),
                tol["position_m"], "m"),
        _within("onboard_vs_reference_heading", ref.get("max_heading_error_rad"),
                tol["heading_rad"], "rad"),
    ]
    distance = report.get("onboard_distance_vs_reference")
    if isinstance(distance, dict) and "passed" in distance:  # ODOM_TWIST DISTANCE
        checks.append(Check("onboard_distance_vs_reference", bool(distance["passed"]),
                            f"DISTANCE beyond the reference's path length by "
                            f"{distance['max_excess_m']} m", dict(distance)))
    for event in report.get("events") or []:  # what a set-pose kept (host.judge.setposekept)
        kept = event.get("kept") if event.get("kind") == "set_pose" else None
        if isinstance(kept, dict):
            checks.append(Check("set_pose_kept", bool(kept["passed"]),
                                f"the pose jumped {kept['position_jump_m']} m, "
                                f"{kept['heading_jump_rad']} rad at an APPLY that kept "
                                f"{', '.join(kept['fields_kept'])}", dict(kept)))
    # on-board vs truth has no limit (the robot's own errors are not the firmware's fault): it
    # is no testcase, so a green CI page never stands for a pose far from the truth
    replay = report.get("replay")
    versus = replay.get("onboard_vs_log") if isinstance(replay, dict) else None
    if isinstance(versus, dict) and "passed" in versus:
        checks.append(Check("replay_vs_logged_firmware", bool(versus["passed"]),
                            "the replayed firmware departs from the logged one", dict(versus)))
    stuck, unjudged = verdictfacts.reasons_of(report)
    for name, reasons in (("encoder_named_after_sent", namesahead.detail(report)),
                          ("e2e_counters_advance", stuck), ("judged", unjudged)):
        if reasons:  # a stuck E2E COUNTER; a check on 0 samples (host.judge.verdictfacts)
            checks.append(Check(name, False, "; ".join(reasons), {"reasons": reasons}))
    stopped = report.get("stopped")
    if stopped:  # a signal ended it before what it was asked: that is no pass
        checks.append(Check("completed", False, stopped_text(stopped), dict(stopped)))
    checks += _recording_check(report.get("recording"))
    if not report.get("passed") and all(check.passed for check in checks):
        checks.append(Check("verdict", False, "the command's verdict is FAIL",
                            {"reasons": report.get("faults")}))
    return checks


def _recording_check(recording: object) -> list[Check]:
    """A failed ``recording`` testcase when a write error stopped ``--log`` (the report's
    ``recording``: the JSON says ``passed: false``, the run exits 2): without it the JUnit read
    0 failures, a green CI page for a log holding part of the run."""
    if not isinstance(recording, dict):
        return []
    said = (f"--log {recording.get('path')}: {recording.get('error')} (recording stopped after "
            f"{recording.get('stopped_after_frames')} frames)")
    return [Check("recording", False, said, dict(recording))]


def _within(name: str, value: float | None, limit: float, unit: str) -> Check:
    """``value <= limit`` (a missing or non-finite value fails)."""
    ok = value is not None and math.isfinite(value) and value <= limit
    figures: dict[str, object] = {f"max_{unit}": value, f"limit_{unit}": limit}
    message = f"{name}: {value} {unit} > limit {limit} {unit}"
    return Check(name, ok, "" if ok else message, figures)


def verdict_check(report: dict[str, Any]) -> list[Check]:
    """The report's own verdict (``passed``, ``faults``) as a testcase, when it has one."""
    if "passed" not in report:
        return []
    reasons = [str(r) for r in report.get("faults") or []]
    if report.get("two_sources"):  # two firmwares on one ID: the pose there is not judged
        reasons.append(str(report["two_sources"]["detail"]))
    if report.get("integrator_mismatch"):  # --integrator not the firmware's (diagnosis)
        reasons.append(str(report["integrator_mismatch"]["detail"]))
    if report.get("judged_floor"):  # too few poses judged (host.judge.judgedfloor)
        reasons.append(str(report["judged_floor"]["detail"]))
    return [Check("verdict", bool(report["passed"]), "; ".join(reasons) or "FAIL",
                  {f"reason_{i + 1}": r for i, r in enumerate(reasons)})]


def umbmark_checks(report: dict[str, Any], prefix: str = "") -> list[Check]:
    """Each direction's centre of gravity and E_max,syst (figures, mm), and the verdict."""
    checks = []
    for direction in ("cw", "ccw"):
        part = report[direction]
        runs = part["runs"]
        finite = all(math.isfinite(r["x_m"]) and math.isfinite(r["y_m"]) for r in runs)
        checks.append(Check(
            f"{prefix}cg_{direction}", finite and len(runs) > 0,
            f"{direction}: a run without a finite return error",
            {"runs": len(runs), "x_cg_mm": part["cg"]["x_m"] * 1e3,
             "y_cg_mm": part["cg"]["y_m"] * 1e3, "r_cg_mm": part["r_cg_m"] * 1e3},
        ))
    emax = report["emax_syst_m"]
    checks.append(Check(f"{prefix}emax_syst", math.isfinite(emax), "E_max,syst not finite",
                        {"emax_syst_mm": emax * 1e3}))
    return checks + ([] if prefix else verdict_check(report))


def calibration_checks(report: dict[str, Any]) -> list[Check]:
    """Both benchmarks' figures, E_max,syst smaller after than before, and the verdict (the
    benchmark before and the verdict alone when the firmware refused the correction: no after)."""
    if report["after"] is None:
        return [*umbmark_checks(report["before"], "before_"), *verdict_check(report)]
    before, after = report["emax_before_m"], report["emax_after_m"]
    improved = math.isfinite(after) and after < before
    figures = {"emax_before_mm": before * 1e3, "emax_after_mm": after * 1e3,
               "improvement": report.get("improvement"),
               "estimated_ed": report["estimated"]["ed"], "estimated_eb": report["estimated"]["eb"]}
    return [
        *umbmark_checks(report["before"], "before_"),
        *umbmark_checks(report["after"], "after_"),
        Check("emax_reduced", improved,
              f"E_max,syst {after * 1e3:.3f} mm after >= {before * 1e3:.3f} mm before", figures),
        *verdict_check(report),
    ]


def experiment_checks(report: dict[str, Any]) -> list[Check]:
    """seed002's two tables (runs and means) as testcases, and the verdict."""
    checks = []
    for key in ("straight_1m", "square_80cm"):
        table = report.get(key)
        if not isinstance(table, dict):
            continue
        runs = table.get("runs") or []
        mean = {f"mean_{k}": v for k, v in (table.get("mean") or {}).items()}
        finite = all(isinstance(v, (int, float)) and math.isfinite(v) for v in mean.values())
        checks.append(Check(key, finite and bool(runs), f"{key}: no runs or a non-finite mean",
                            {"runs": len(runs), **mean}))
    return checks + verdict_check(report)
