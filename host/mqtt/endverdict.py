"""One bridged robot's verdict when its watch ends (``odocan bridge``'s verdict line, exit code).

The retained ``status`` carried the verdicts (``pose_wrongs``, ``distance``, ``twist``) and the
bridge still exited 0: a CI job running a sim, a firmware and a bridge could not fail on a wrong
pose (issue #11: the rig never shows OK while the pose it reports is wrong). Now, after
``RobotTelemetry.end_watch``, each robot gets one line, the monitor's FAIL reasons
(``host.judge.watchverdict``) joined by "; "::

    FAIL: the on-board pose was wrong in 1 episode (...); judged as robot 'kobuki' (--robot)
    PASS: the on-board pose right in 598 samples, ODOM_TWIST DISTANCE in 59 and its speeds in 598
    UNJUDGED: no on-board pose compared with the reference: nothing judged (--require-firmware
    fails it)

FAIL (exit 1) when the pose was wrong at any time of the watch, DISTANCE or the twist speeds
wrong once, two firmwares on the bus, or (``require_firmware``) when nothing was judged; the
firmware's PROFILE page against ``--robot``, when it differs, follows on the line (a firmware set
up for another robot reads as wrong).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from odocan.host.judge.watchverdict import REQUIRE_FIRMWARE, failures, nothing_judged

if TYPE_CHECKING:
    from odocan.host.mqtt.telemetry import RobotTelemetry


@dataclass(frozen=True)
class EndVerdict:
    """A robot's verdict: ``text`` its line (``FAIL: ...``, ``PASS: ...``, ``UNJUDGED: ...``),
    ``failed`` whether it fails the bridge (exit 1)."""

    text: str
    failed: bool


def end_verdict(telemetry: RobotTelemetry, *, profile_name: str | None = None,
                require_firmware: bool = False) -> EndVerdict:
    """``telemetry``'s verdict (module docstring), its watch ended (``end_watch``);
    ``profile_name``: the robot profile it was judged as (``--robot``), said beside a wrong pose."""
    judged_as = "" if profile_name is None else f"; judged as robot {profile_name!r} (--robot)"
    fails = failures(telemetry.tracker, telemetry.distance, telemetry.twist, telemetry.sources,
                     judged_as)
    compared = telemetry.tracker.vs_reference.samples
    why = nothing_judged(telemetry.db, telemetry.frames, compared)
    if why and require_firmware:
        fails.append(f"{why} {REQUIRE_FIRMWARE}")
    if fails:
        return EndVerdict("FAIL: " + "; ".join(fails) + _mismatch(telemetry), True)
    if why:
        return EndVerdict(f"UNJUDGED: {why} (--require-firmware fails it)"
                          + _mismatch(telemetry), False)
    distance, twist = telemetry.distance.samples, telemetry.twist.samples
    twists = (f", ODOM_TWIST DISTANCE in {distance} and its speeds in {twist}"
              if distance or twist else ", no ODOM_TWIST judged")
    return EndVerdict(f"PASS: the on-board pose right in {compared} samples{twists}"
                      + _mismatch(telemetry), False)


def _mismatch(telemetry: RobotTelemetry) -> str:
    """``; profile mismatch: ...`` when the firmware's PROFILE page differs from ``--robot``
    (``host.mqtt.liveprofile``), "" else."""
    section = telemetry.profile.section
    if section is None or section.get("verdict") != "MISMATCH" or not section.get("detail"):
        return ""
    return f"; {section['detail']}"
