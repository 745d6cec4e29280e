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
    UNJUDGED: 1 re-prime declared after a stall before the first pose, the power-up not
    proven: ... (``livereprime.unbounded_why``: a PASS would rest on a pose nothing bounds)
    UNJUDGED: the firmware stalled before its first pose after its power-up (INIT at UPTIME 0)
    while the robot moved: ... (``livefirst.unproven_why``: the same)
    UNJUDGED: no ODOM_TWIST frame in the watch: twist and DISTANCE not judged (--require-firmware
    fails it) (``watchverdict.twist_unheard``: a check on 0 samples is no pass)
    FAIL: 991 of 1000 ODOM_POSE_X ... frames E2E REPEATED: the sender's E2E COUNTER does not
    advance ... (``watchverdict.stuck_counters``: the host refuses those frames)

Without ``--robot``, a firmware whose PROFILE page is not the default robot's is not judged
(``host.judge.liverobot``: judging it as pmir FAILed a correct firmware for an option not
given)::

    UNJUDGED: the firmware runs a different profile than the default robot pmir: give --robot
    (--require-firmware fails it); profile mismatch: ...

FAIL (exit 1) when the pose was wrong at any time of the watch, DISTANCE or the twist speeds
wrong once, two firmwares on the bus, or (``require_firmware``) when nothing was judged; the
firmware's PROFILE page against ``--robot``, when it differs, follows on the line (a firmware set
up for another robot reads as wrong).

The verdict is data too (``EndVerdict.as_dict``): the retained ``offline`` status carries it as
``watch_verdict`` (``host.mqtt.bridge``), so a dashboard that subscribes after the bridge stopped
reads what the line said: ``{"verdict": "FAIL", "reason": "the on-board pose was wrong ...",
"pose_error": {...}}``, ``pose_error`` the worst wrong episode the line names (null when it
names none), ``loop`` null (``odocan fleet``'s statuses carry the same verdict, their real-time
loop's deadline figures in ``loop``: ``host.mqtt.fleetjudge``). Computed once, when the watch
ends, before the links say ``offline``: the line and the status are the same verdict.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any, Protocol

from odocan.host.judge.watchline import VerdictName as VerdictName
from odocan.host.judge.watchline import Watched, watch_verdict

if TYPE_CHECKING:
    from odocan.host.mqtt.telemetry import RobotTelemetry


@dataclass(frozen=True)
class EndVerdict:
    """A robot's verdict: ``verdict`` its name, ``reason`` what its line says after the name,
    ``pose_error`` the worst wrong pose episode the reason names (``posewrongs.Episode`` as a
    dict: ``dpos_mm``, ``beyond_mm``, ``dheading_mrad``, ``t_s``, ``enc_seq``, ...; None when
    it names none); ``loop``: the deadline figures of the fleet's real-time loop that ran the
    robot (``host.mqtt.fleetjudge.loop_figures``; None: a bridge has no such loop)."""

    verdict: VerdictName
    reason: str
    pose_error: dict[str, Any] | None = None
    loop: dict[str, Any] | None = None

    @property
    def text(self) -> str:
        """Its line: ``FAIL: ...``, ``PASS: ...``, ``UNJUDGED: ...``."""
        return f"{self.verdict}: {self.reason}"

    @property
    def failed(self) -> bool:
        """Whether it fails the bridge (exit 1)."""
        return self.verdict == "FAIL"

    def as_dict(self) -> dict[str, Any]:
        """``{"verdict", "reason", "pose_error", "loop"}`` (JSON-ready): the ``offline`` status's
        ``watch_verdict``."""
        return asdict(self)


class EndJudge(Protocol):
    """What judges a bridge's robots when their watch ends (``Bridge(end_rule=...)``):
    ``EndRule`` (``odocan bridge``), ``fleetjudge.FleetEndRule`` (``odocan fleet``)."""

    def judge(self, telemetry: RobotTelemetry, profile_name: str | None) -> EndVerdict:
        """``telemetry``'s verdict, its watch ended; ``profile_name``: the robot profile it is
        judged as (``--robot``)."""
        ...


@dataclass(frozen=True)
class EndRule:
    """How a bridge judges its robots when their watch ends: ``require_firmware`` makes a watch
    that judged nothing FAIL (``--require-firmware``)."""

    require_firmware: bool = False

    def judge(self, telemetry: RobotTelemetry, profile_name: str | None) -> EndVerdict:
        """``telemetry``'s verdict by this rule (``end_verdict``)."""
        return end_verdict(telemetry, profile_name=profile_name,
                           require_firmware=self.require_firmware)


def end_verdict(telemetry: RobotTelemetry, *, profile_name: str | None = None,
                require_firmware: bool = False) -> EndVerdict:
    """``telemetry``'s verdict (module docstring), its watch ended (``end_watch``);
    ``profile_name``: the robot profile it was judged as (``--robot``), said beside a wrong pose."""
    judged_as = "" if profile_name is None else telemetry.robot.judged_as()  # (liverobot)
    name, reasons = watch_verdict(Watched(
        telemetry.tracker, telemetry.distance, telemetry.twist, telemetry.sources,
        telemetry.kept, telemetry.db, telemetry.frames, telemetry.e2e.counts(),
        telemetry.robot.unjudged, ahead=tuple(telemetry.ahead.why())), judged_as=judged_as,
        require_firmware=require_firmware)
    return EndVerdict(name, "; ".join(reasons) + _mismatch(telemetry),
                      worst_episode(telemetry) if name == "FAIL" else None)


def worst_episode(telemetry: RobotTelemetry) -> dict[str, Any] | None:
    """The worst wrong pose episode, as the FAIL line names it (``failures``: when an episode
    was latched), as a dict; None when the pose was never wrong."""
    wrongs = telemetry.tracker.wrongs
    if not wrongs.count or wrongs.worst is None:
        return None
    return asdict(wrongs.worst)


def _mismatch(telemetry: RobotTelemetry) -> str:
    """``; profile mismatch: ...`` when the firmware's PROFILE page differs from ``--robot``
    (``host.mqtt.liveprofile``), "" else."""
    section = telemetry.profile.section
    if section is None or section.get("verdict") != "MISMATCH" or not section.get("detail"):
        return ""
    return f"; {section['detail']}"
