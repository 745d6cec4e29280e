"""The judged floor (rule: a PASS must never hide a wrong pose): a verdict that compared fewer
than half of the on-board poses with the reference is no PASS.

The judge leaves a pose out when it cannot tell which encoder frame it was computed from (the
frame it names is not in the log, or has a twin: ``samples.match_encoder``). Each such pose is
one the verdict says nothing about. Two firmwares on one ID merged in one log left 998 of 1000
pose frames out and PASSed on the one sample left, hiding a firmware 50 mm wrong (the trial of
issue #11; ``posestreams`` now tells that case by name). Whatever the cause, a PASS resting on
so few samples is a guess: a pose error that does not last (one bad frame, a wrong field) is
seen with the chance that its pose was judged, so below one half the judge is more likely to
miss it than to see it, and an error that lasts is seen only after the next judged sample.
The floor is ``JUDGED_FLOOR`` of the poses sent (judged + unmatched; the poses a stall's
re-placement or a reboot's start leave out are not counted as sent: they are judged by their
own rules; the first pose after a silence is counted, judged by ``stallfirst`` or not): the
verdict is UNJUDGED, ``passed`` false (exit 1), and says how many were judged.

The floor is for poses left out because of twins (encoder frames a second CRC-right sender
offered: a forger, or a second robot): it applies when the twins outnumber the poses judged,
i.e. most of what was left out could have been someone else's frame. Poses left out for the
log's own limits are not a second sender's doing and stay judged on what remains: a starved
recorder's bunched stamps leave out up to 78 % of a correct firmware's poses
(``tests/test_live_settle.py``: a plain 50 % floor FAILed those correct firmwares, whose judged
samples are spread over the whole drive, so a lasting error still shows), the encoder frames a
logger missed leave out the poses naming them (every 7th lost: 1 in 7); ``judged_fraction``
says it either way, and the summary's ``judged`` line."""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any, Final, ParamSpec, Protocol, TypeVar

JUDGED_FLOOR: Final = 0.5  # of the on-board poses sent, judged, for a PASS


class _Verdict(Protocol):
    report: dict[str, Any]
    passed: bool


def judged_share(report: dict[str, Any]) -> tuple[int, int] | None:
    """(poses judged, poses sent) of a report (``samples``: ``onboard`` judged,
    ``unmatched_sent`` the whole poses the halves left out stand for, ``lonehalves``; else
    ``unmatched_poses``, those halves, X and Y each, half up; ``lone_halves_judged`` /
    ``_unjudged``: halves whose partner was lost, ``host.judge.lonehalves``); None without
    samples."""
    samples = report.get("samples") or {}
    if "onboard" not in samples:
        return None
    judged = int(samples["onboard"]) + int(samples.get("stall_first_judged") or 0) + int(
        samples.get("lone_halves_judged") or 0)  # a half without its partner: one pose sent
    left = int(samples.get("stall_first_unjudged") or 0) - int(
        samples.get("stall_first_unmatched") or 0) + int(samples.get("lone_halves_unjudged") or 0)
    halves = int(samples.get("unmatched_poses") or 0)  # (the streamed analysis: halves only)
    return judged, judged + int(samples.get("unmatched_sent", (halves + 1) // 2)) + left


def mark_floor(report: dict[str, Any]) -> dict[str, Any]:
    """``report`` with ``samples.judged_fraction`` and, below ``JUDGED_FLOOR``, ``judged_floor``
    (its reason) and ``passed`` false (module docstring)."""
    share = judged_share(report)
    if share is None or share[1] <= 0:
        return report
    judged, sent = share
    report["samples"]["judged_fraction"] = judged / sent
    twins = int((report.get("reference_breaks") or {}).get("twins") or 0)
    if judged >= JUDGED_FLOOR * sent or twins <= judged:  # not most left out for twins
        return report
    report["judged_floor"] = {
        "judged_poses": judged, "poses": sent, "floor": JUDGED_FLOOR,
        "detail": f"only {judged} of {sent:g} on-board poses judged ({100 * judged / sent:.3g} %; "
                  f"{twins} encoder frames have a twin, a second sender's): a PASS needs at "
                  f"least {100 * JUDGED_FLOOR:g} %"}
    report["passed"] = False
    return report


P = ParamSpec("P")
R = TypeVar("R", bound=_Verdict)


def floored(analyze: Callable[P, R]) -> Callable[P, R]:
    """``analyze`` whose result's report and verdict have the floor (``mark_floor``)."""

    @functools.wraps(analyze)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        result = analyze(*args, **kwargs)
        mark_floor(result.report)
        result.passed = result.passed and bool(result.report["passed"])
        return result

    return wrapper
