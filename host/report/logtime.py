"""The summary's clock: seconds since the log's first frame, not the log's bus time.

A capture from a real bus (``odocan monitor --log``, candump, a logger's ASC or BLF) stamps its
frames in epoch seconds: "DEGRADED since 1796342025.59 s" reads as noise. The summary says its
times from the log's first frame (the report's ``first_frame_s``) and names that frame's time
once, as ISO 8601 UTC when the stamps are absolute; the JSON report's ``t_s`` stay bus times
(its consumers read them so). A log of ``odocan run`` starts at 0: its summary is unchanged.
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

ABSOLUTE_S = 1e8  # a first frame past this (over 3 years) is a wall-clock stamp, not an uptime


def origin_s(report: dict[str, Any]) -> float:
    """Bus time (s) the summary's times count from: the log's first frame (0 when unknown)."""
    return float(report.get("first_frame_s") or 0.0)


def start_text(report: dict[str, Any]) -> str | None:
    """The summary's ``log`` line: when the first frame was, the times below counting from it;
    None for a log from bus time 0 (``odocan run``'s), whose times need no origin."""
    first_s = origin_s(report)
    if first_s == 0.0:
        return None
    if first_s > ABSOLUTE_S:
        stamp = datetime.fromtimestamp(first_s, tz=UTC).isoformat(timespec="milliseconds")
        when = stamp.replace("+00:00", "Z")
    else:
        when = f"at bus time {first_s:.3f} s"
    return f"first frame {when}; the times below are seconds since it"
