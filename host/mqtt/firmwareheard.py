"""How long ago a live bridge last heard the firmware (issue #11 item 5: silence is not OK).

A bridge keeps publishing its ``status`` once a second while the firmware behind it is dead:
before this, the retained status still carried the firmware's last summary (``state`` OK) and
nothing else, so ``odocan monitor --mqtt`` showed the robot OK 6 s after a ``kill -9`` of its
firmware (its row's age is the bridge's last message, which stays fresh). The status now
carries ``firmware_heard``: the age of the firmware node's latest frame (an ODOM_POSE_X or an
ODOM_STATUS page whose CRC holds, by its bus timestamp, against the wall clock the status is
stamped with), its DBC timeout (``NODE_TIMEOUT_CYCLES`` x its fastest cycle, as the monitor's
``node_ages``) and ``stale``; the fleet view then shows the robot ``STALE``, saying what the
firmware last said.

Only a live bus's frames carry wall-clock stamps (python-can's interfaces stamp with the epoch);
a stamp that cannot be one (a hardware clock from 0, a lockstep fleet's bus time) gives
``age_s`` and ``stale`` None: unknown, never a made-up age.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from cantools.database.can import Database

from odocan.host.judge.monitorvalues import NODE_TIMEOUT_CYCLES
from odocan.host.judge.sources import FIRMWARE_NODE

if TYPE_CHECKING:
    from odocan.host.mqtt.telemetry import RobotTelemetry

MAX_PLAUSIBLE_AGE_S = 7 * 86400.0  # an age beyond a week: the stamps are no wall clock
CLOCK_SLACK_S = 1.0  # a stamp this far ahead of the wall clock is still taken as one (jitter)


def node_timeout_s(db: Database, node: str = FIRMWARE_NODE) -> float | None:
    """``NODE_TIMEOUT_CYCLES`` x the fastest cycle of ``node``'s cyclic messages (s)."""
    cycles = [m.cycle_time for m in db.messages
              if node in m.senders and m.send_type == "Cyclic" and m.cycle_time]
    return NODE_TIMEOUT_CYCLES * min(cycles) / 1e3 if cycles else None


def firmware_heard(heard_s: list[float | None], timeout_s: float | None,
                   now_unix_s: float) -> dict[str, Any] | None:
    """``{"node", "age_s", "timeout_s", "stale"}`` of the latest of ``heard_s`` (bus stamps of
    the firmware's frames) at ``now_unix_s``; None before any was heard."""
    stamps = [s for s in heard_s if s is not None]
    if not stamps or timeout_s is None:
        return None
    age_s: float | None = now_unix_s - max(stamps)
    if age_s is not None and not -CLOCK_SLACK_S <= age_s <= MAX_PLAUSIBLE_AGE_S:
        age_s = None
    return {"node": FIRMWARE_NODE, "age_s": None if age_s is None else round(max(age_s, 0.0), 3),
            "timeout_s": timeout_s, "stale": None if age_s is None else age_s > timeout_s}


def telemetry_heard(telemetry: RobotTelemetry, now_unix_s: float) -> dict[str, Any] | None:
    """``firmware_heard`` of a live bridge's robot: its latest pose or status page heard
    (``SourceWatch.pose_s``, ``status_last``; CRC holding, any sequence)."""
    src = telemetry.sources
    last_page_s = src.status_last[0] if src.status_last is not None else None
    return firmware_heard([src.pose_s, last_page_s], node_timeout_s(telemetry.db), now_unix_s)
