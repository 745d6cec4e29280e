"""What a PASS must not hide, read from a finished report: checks with nothing to judge, and an
E2E COUNTER that does not advance (an outside trial's own firmware, written from the DBC).

* ``unheard``: a firmware that never sends ODOM_TWIST (a cyclic 20 ms message of the DBC) got a
  PASS with the twist and DISTANCE checks ``passed: true`` on 0 samples, and so did a DBC
  without ODOM_TWIST's DISTANCE. A check on 0 samples judged nothing: the verdict is UNJUDGED
  (exit 1, as ``replay``'s), one reason naming what was never heard ("no ODOM_TWIST frame in
  60.0 s: twist and DISTANCE not judged"), never a PASS. A log too short for the firmware to
  say anything gets the same clear UNJUDGED, not a FAIL.
* ``not_advancing``: a firmware whose E2E COUNTER never increments has nearly every frame
  refused as REPEATED (991 of 1000 poses): the host may use none of them, so the firmware is
  wrong whatever the few accepted poses say. The FAIL names it (``STUCK_TEXT``), where it
  blamed reboots that never happened (``host.judge.bootticks``' ``REPEAT_NO_BREAK``) or passed
  on the one pose accepted.

``mark(report)`` adds both to the report (``unjudged``: ``{"reasons", "judged_passed"}``;
``e2e_not_advancing``: ``[{"message", "repeated", "frames"}]``) and clears ``passed``; the
summary (``host.report.summary``), the batch's rows and the JUnit checks read them. The live
judges say the same from their own counts (``host.judge.watchverdict``).
"""

from __future__ import annotations

from typing import Any

TWIST = "ODOM_TWIST"  # the cyclic message the twist and DISTANCE checks judge
MIN_FRAMES = 16  # a message heard fewer times than one COUNTER lap says nothing of its COUNTER


def unheard(report: dict[str, Any]) -> list[str]:
    """The reasons nothing was judged by a check that passed on 0 samples ([] when none)."""
    frames = report.get("frames") or {}
    seconds = float(report.get("sim_seconds") or 0.0)
    twist = report.get("onboard_twist_vs_reference") or {}
    distance = report.get("onboard_distance_vs_reference") or {}
    heard = int(frames.get(TWIST) or 0)
    if not heard:
        return [f"no {TWIST} frame in {seconds:.1f} s: twist and DISTANCE not judged"]
    unjudged = [what for what, check in (("speeds", twist), ("DISTANCE", distance))
                if check and not check.get("samples")]
    if not unjudged:
        return []
    return [f"{TWIST} {' and '.join(unjudged)} judged on none of its {heard} frames in "
            f"{seconds:.1f} s: not judged"]


def not_advancing(e2e: dict[str, dict[str, int]]) -> list[dict[str, Any]]:
    """The messages most of whose frames (of at least ``MIN_FRAMES``) were E2E REPEATED."""
    stuck = []
    for name, counts in e2e.items():
        total = sum(int(v) for v in counts.values())
        repeated = int(counts.get("repeated", 0))
        if total >= MIN_FRAMES and 2 * repeated > total:
            stuck.append({"message": name, "repeated": repeated, "frames": total})
    return stuck


def stuck_text(stuck: list[dict[str, Any]]) -> str:
    """``991 of 1000 ODOM_POSE_X frames E2E REPEATED, ...: the sender's E2E COUNTER does not
    advance (the host must refuse those frames)``."""
    each = ", ".join(f"{s['repeated']} of {s['frames']} {s['message']}" for s in stuck)
    return (f"{each} frames E2E REPEATED: the sender's E2E COUNTER does not advance (a host "
            "refuses those frames)")


def mark(report: dict[str, Any]) -> bool:
    """Add ``unjudged`` and ``e2e_not_advancing`` to ``report`` (module docstring), clear its
    ``passed`` for either; returns ``passed``. Marking twice changes nothing."""
    if "unjudged" in report or "e2e_not_advancing" in report:
        return bool(report.get("passed"))
    stuck = not_advancing(report.get("e2e") or {})
    if stuck:
        report["e2e_not_advancing"] = stuck
        report["passed"] = False
    reasons = unheard(report)
    if reasons:
        report["unjudged"] = {"reasons": reasons, "judged_passed": bool(report.get("passed"))}
        report["passed"] = False
    return bool(report.get("passed"))


def verdict_name(report: dict[str, Any]) -> str:
    """PASS, FAIL, or UNJUDGED (what was judged passed, a check judged nothing)."""
    if report.get("passed"):
        return "PASS"
    unjudged = report.get("unjudged") or {}
    return ("UNJUDGED" if unjudged.get("judged_passed") and not report.get("stopped")
            and not report.get("e2e_not_advancing") else "FAIL")


def reasons_of(report: dict[str, Any]) -> tuple[list[str], list[str]]:
    """(FAIL reasons, UNJUDGED reasons) ``mark`` added to ``report``, in words."""
    stuck = report.get("e2e_not_advancing") or []
    unjudged = (report.get("unjudged") or {}).get("reasons") or []
    return ([stuck_text(stuck)] if stuck else []), list(unjudged)
