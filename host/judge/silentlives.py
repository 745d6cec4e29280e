"""The lives ``analyze`` could not compare (no on-board sample names an encoder frame of theirs),
reported rather than dropped.

A life cut at an applied ODOM_CONFIG (or a set-pose, a reboot) whose firmware integrates no
encoder frame has no on-board sample of its own: its poses, if sent, keep naming the last frame
integrated before the cut (``samples._held``). A user's config of 16-bit counters on a robot
whose counts set the wire's top 8 bits makes a correct firmware refuse every frame
(IMPLAUSIBLE_STEP, ``firmware.encoders._refuse_unused_bits``) and hold its pose and ODOM_TWIST
on that frame (the DBC: the values "after integrating encoder frame ENC_COUNTER"). Before,
``analyze`` dropped such a life silently: its 20 s (of 45) missing from the E2E table (counted
in no category), its config event gone, the verdict a PASS that did not say what it had not
judged. Now its frames are counted, its config (or set-pose) event is there, and an
``unjudged`` event names the stretch, which the summary's verdict line says
(``host.report.summary.kept_unjudged``); the live monitor and bridge judge the held samples
against the frame they name (``livewindow.named_in_window``) and agree.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.finalstate import firmware_fields
from odocan.host.judge.liveconfig import config_text
from odocan.host.judge.reboots import Life
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import UNKNOWN, check_frames
from odocan.sim.robot import RobotProfile

if TYPE_CHECKING:
    from odocan.host.protocol.dbcplan import DatabaseSpec


@dataclass(frozen=True)
class SilentLife:
    """A life without on-board samples: its E2E counts, its first and last frame's bus time,
    what it says (``events``)."""

    e2e: dict[str, dict[str, int]]
    unknown: dict[str, int]
    events: list[dict[str, Any]]


def silent_life(frames: FrameArrays, life: Life, robot: RobotProfile, integrator: str,
                db: DatabaseSpec, why: str) -> SilentLife | None:
    """``life`` (no on-board sample: ``why``, the ``AnalysisError``'s words) with the robot and
    integrator it would have been judged with; None for a life without an encoder frame the
    firmware could have integrated (a set-pose in the log's first millisecond: nothing there to
    judge, left out as before and as the streamed judge leaves it)."""
    part = frames.select(life.index)
    e2e, accepted = check_frames(part, db)
    decoder = BulkDecoder(db)
    if not accepted[decoder.decode(part, "WHEEL_ENCODERS")["index"]].any():
        return None
    t0, t1 = float(part.timestamp_s[0]), float(part.timestamp_s[-1])
    final = firmware_fields(part, accepted, decoder).get("firmware_final") or {}
    poses = decoder.decode(part, "ODOM_POSE_Y")["index"]
    held = ("the pose and ODOM_TWIST held on a frame integrated before"
            if accepted[poses].any() else "no on-board pose sent")
    state = f" (the firmware {final['state']} {final['reason']})" \
        if final.get("state") not in (None, "OK") else ""
    events: list[dict[str, Any]] = []
    start = life.t_s if life.t_s is not None else t0
    if life.config is not None:
        events.append({"kind": "config", "t_s": life.t_s, "parameters": dict(life.config.staged),
                       "detail": config_text(robot.counts_per_rev, robot.wheel_radius_left_m,
                                             robot.wheel_radius_right_m, robot.wheelbase_m,
                                             integrator)})
    events.append({"kind": "unjudged", "t_s": start, "until_s": t1, "seconds": t1 - start,
                   "detail": f"{t1 - start:.2f} s from {start:.3f} s not judged: no on-board "
                             f"pose names an encoder frame there{state}: {held} ({why})"})
    return SilentLife({n: c for n, c in e2e.items() if n != UNKNOWN}, e2e[UNKNOWN], events)


def add_silent(report: dict[str, Any], silent: list[SilentLife]) -> None:
    """``report`` (``reboots.merge``'s) with the silent lives' E2E counts and events."""
    for life in silent:
        e2e = report["e2e"]
        for name, counts in life.e2e.items():
            into = e2e.setdefault(name, dict.fromkeys(counts, 0))
            for key, n in counts.items():
                into[key] = into.get(key, 0) + n
        for key, n in life.unknown.items():
            report["unknown_frames"][key] = report["unknown_frames"].get(key, 0) + n
        report["events"] = sorted([*report["events"], *life.events], key=lambda e: e["t_s"])
