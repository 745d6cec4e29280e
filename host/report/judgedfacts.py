"""What the judge could judge, as the text summary says it (``host.report.summary``): how many
of the on-board poses it compared (``host.judge.judgedfloor``)."""

from __future__ import annotations

from typing import Any


def judged_fact(report: dict[str, Any]) -> tuple[str, str] | None:
    """The ``judged`` line: poses compared of those sent; None without the count."""
    samples = report.get("samples") or {}
    if "judged_fraction" not in samples:
        return None
    judged = int(samples["onboard"])
    sent = judged + int(samples.get("unmatched_poses") or 0) / 2
    return "judged", (f"{judged} of {sent:g} on-board poses compared with the reference "
                      f"({100 * samples['judged_fraction']:.4g} %)")

