"""The robot's plausibility bound in force for the E2E checks of one analysis
(``host.protocol.e2e_bound``: a skip proof whose step the bound refuses is the bound's, not the
E2E check's; issue #11, rule 5).

``bounded`` wraps an analysis entry (``analysis.analyze``, ``stream_analysis.analyze_file``):
every E2E check run inside it reads the bound of the robot it judges with (its
``max_wheel_speed_mm_s`` keyword, else the profile's), the counters' width on the wire its
``counter_bits`` (at most 24), the counts decoded by the analysis's DBC (its ``db`` keyword).
A bound of None (steps unbounded) sets none."""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

from odocan.host.judge.reference import PROFILE_SPEED, Geometry, SpeedBound
from odocan.host.judge.samples import WIRE_COUNTER_BITS
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e_bound import StepBound, step_bound
from odocan.sim.robot import RobotProfile

if TYPE_CHECKING:
    from odocan.host.protocol.dbcplan import DatabaseSpec

F = TypeVar("F", bound=Callable[..., Any])


def bound_of(robot: RobotProfile, max_wheel_speed_mm_s: SpeedBound = PROFILE_SPEED,
             db: DatabaseSpec | None = None) -> StepBound | None:
    """The firmware's per-period step bound in counts for ``robot`` (None: unbounded), its
    counts read by the DBC ``db`` (None: odocan's)."""
    geometry = Geometry.of(robot)
    speed_mm_s = geometry.speed_bound_mm_s(max_wheel_speed_mm_s)
    if speed_mm_s is None:
        return None
    left, right = geometry.period_counts(speed_mm_s)
    return StepBound(left, right, min(robot.counter_bits, WIRE_COUNTER_BITS),
                     BulkDecoder(db if db is not None else default_plan()))


def bounded(analyze: F) -> F:
    """``analyze(frames_or_path, robot, ...)`` with ``bound_of`` its robot in force."""
    @functools.wraps(analyze)
    def wrapper(source: Any, robot: RobotProfile, *args: Any, **kwargs: Any) -> Any:
        speed = kwargs.get("max_wheel_speed_mm_s", PROFILE_SPEED)
        with step_bound(bound_of(robot, speed, kwargs.get("db"))):
            return analyze(source, robot, *args, **kwargs)
    return wrapper  # type: ignore[return-value]
