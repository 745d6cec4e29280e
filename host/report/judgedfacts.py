"""What the judge could judge, as the text summary says it (``host.report.summary``): how many
of the on-board poses it compared (``host.judge.judgedfloor``), and where it re-placed the
reference (``reference_breaks``: after a gap of the log, a stall or a hold the position across it
is judged only within the placement's allowance, so the summary must not say only "exact from
power-up" while the JSON says the reference moved)."""

from __future__ import annotations

from typing import Any

from odocan.host.judge.judgedfloor import judged_share


def judged_fact(report: dict[str, Any]) -> tuple[str, str] | None:
    """The ``judged`` line: poses compared of those sent; None without the count."""
    samples = report.get("samples") or {}
    if "judged_fraction" not in samples:
        return None
    judged, sent = judged_share(report) or (0, 0)
    return "judged", (f"{judged} of {sent:g} on-board poses compared with the reference "
                      f"({100 * samples['judged_fraction']:.4g} %)" + _first_said(report))


def _first_said(report: dict[str, Any]) -> str:
    """The poses sent first after a silence (``host.judge.stallfirst``), when there were any."""
    first = report.get("stall_first_pose") or {}
    if not first.get("judged") and not first.get("unjudged"):
        return ""
    said = f"; {first['judged']} sent first after a silence judged by the poses around it"
    if max(first.get("max_position_beyond_m") or 0.0,
           first.get("max_heading_beyond_rad") or 0.0) > 0:
        said += (f" ({first['max_position_beyond_m'] * 1e3:.4g} mm, "
                 f"{max(first['max_heading_beyond_rad'], 0.0) * 1e3:.4g} mrad beyond them "
                 f"at {first['worst_at_s']:.3f} s)")
    if first.get("max_resume_beyond_m") is not None and first["max_resume_beyond_m"] > 0:
        said += (f"; the pose at {first['resume_at_s']:.3f} s lies "
                 f"{first['max_resume_beyond_m'] * 1e3:.4g} mm beyond any the firmware can "
                 "resume at from its pose before the stall (a jump, no placement)")
    if first.get("unjudged"):
        said += (f", {first['unjudged']} not judged (no neighbour names a frame it may name, "
                 "or only one side's does)")
    return said


def placed_fact(report: dict[str, Any]) -> tuple[str, str] | None:
    """The ``re-placed`` line: the reference's placements after gaps, stalls and holds, each
    with the largest offset absorbed and its allowance; None when there were none."""
    breaks = report.get("reference_breaks") or {}
    said = []
    if breaks.get("gap_placements"):
        said.append(_placements(breaks["gap_placements"], "a gap of the log",
                                breaks["max_gap_offset_absorbed_m"],
                                breaks["gap_offset_allowance_m"]))
    if breaks.get("stall_placements"):
        said.append(_placements(breaks["stall_placements"], "a firmware stall or hold",
                                breaks["max_offset_absorbed_m"], breaks["offset_allowance_m"]))
    if breaks.get("free_gap_placements"):
        said.append(f"{breaks['free_gap_placements']} after a gap with no bound (no plausibility "
                    "bound configured): the position across it is not judged")
    if not said:
        return None
    return "re-placed", "; ".join(said)


def _placements(count: int, after: str, absorbed_m: float, allowance_m: float) -> str:
    return (f"{count} after {after} (at most {absorbed_m * 1e3:.4g} mm absorbed, within "
            f"{allowance_m * 1e3:.4g} mm allowed): the position across it is judged only within "
            "that allowance")
