"""A test driver for odometry firmware on a CAN bus: what the pytest fixture ``odocan_rig`` returns.

``OdocanRig`` puts a firmware under test and lets a test drive it and judge it from the bus only:

* **drive**: an open-loop scenario (``drive``), navigation goals for the firmware's own
  controller (``goto``, ``path``, ``run_until_reached``), or just time (``step``, ``run_until``);
* **read**: every frame the host heard, decoded by cantools from the DBC after its E2E check
  (``frames``, ``latest``, ``nav_status``, ``odom_status``), the on-board ``pose``, the ground
  ``truth``, the float64 ``reference`` and the analysis ``report`` (``host.analysis``);
* **judge**: ``assert_pose_matches_reference``, ``assert_near_truth``, ``assert_reached`` raise an
  ``AssertionError`` whose message carries the numbers.

The firmware runs on one of two backends (``backends.py``): lockstep with ours, or any firmware
that speaks the DBC on a real bus. The rig's parts: ``options.py`` (what a rig is made of),
``host.protocol.heard`` (what the host heard), ``host.protocol.session`` (commands, their ACKs
and NAV_STATUS: the same session the experiments drive with), ``judging.py`` (the assertions),
this module (driving and reading).

Times (``timestamp_s``, ``now_s``) are seconds since the recording started: simulated seconds in
lockstep, wall-clock seconds on a real bus.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import Any

import can

from odocan.host.judge.analysis import Analysis, analyze
from odocan.host.protocol.commands import CommandEncoder
from odocan.host.protocol.heard import UnknownMessageError
from odocan.host.protocol.pose import Pose
from odocan.host.protocol.secoc import SecocSigner, load_secoc_key
from odocan.host.protocol.session import CommandNotAcked, CommandSession, SecocUnsynchronised
from odocan.host.testkit.backends import (
    EXTERNAL_ACK_TIMEOUT_S,
    Backend,
    ExternalBackend,
    LockstepBackend,
)
from odocan.host.testkit.judging import RigAssertions
from odocan.host.testkit.options import CommandRefused, RigOptions, TestkitError, fault_spec
from odocan.sim.board import TICK_S
from odocan.sim.scenarios import Scenario, get_scenario

_TRACKING_POSES = 10  # pose frames in a row that must name our encoder frames (0.2 s)
# DEGRADED reasons only a set-pose clears (attach sets the pose next): the firmware still tracks
_POSE_ASKED = ("COUNTER_RESET", "POSE_UNCERTAIN")
_TRACKING_WINDOW_S = 0.05  # ... one sent at most this long before the pose frame

# --- the driver -------------------------------------------------------------------------------


class OdocanRig(RigAssertions):
    """Drive a firmware under test and judge its odometry from the bus (module docstring)."""

    def __init__(
        self, backend: Backend, options: RigOptions, encoder: CommandEncoder | None = None
    ) -> None:
        self.backend = backend
        self.options = options
        self.robot = options.profile()
        self.session = CommandSession(
            backend.recorder,
            backend.send,
            backend.advance_until,
            ack_timeout_s=backend.ack_timeout_s,
            encoder=encoder,
            signer=SecocSigner(load_secoc_key(options.secoc_key)) if options.secoc_key else None,
        )
        self._next_goal_id = 1
        self._last_goal_id: int | None = None
        self._t0 = 0.0
        self._analysis: tuple[int, Analysis] | None = None
        self.closed = False

    # --- set-up and teardown ----------------------------------------------------------------

    @property
    def mode(self) -> str:
        """``"lockstep"`` (our firmware, simulated time) or ``"external"`` (a real bus)."""
        return self.backend.mode

    @property
    def integrator(self) -> str:
        """The integrator the firmware runs (and the reference uses)."""
        return self.options.integrator

    def attach(self, timeout_s: float) -> None:
        """External firmware: wait for it, configure it, put it at the origin, start recording."""
        heard = self.backend.advance_until(lambda: self.odom_status is not None, timeout_s)
        if not heard:
            raise TestkitError(
                f"no ODOM_STATUS from the firmware within {timeout_s:g} s: is it running on "
                "this bus?"
            )
        p = self.robot
        self._refused_as_assertion(
            lambda: self.session.configure(
                counts_per_rev=p.counts_per_rev,
                wheel_radius_left_m=p.wheel_radius_left_m,
                wheel_radius_right_m=p.wheel_radius_right_m,
                wheelbase_m=p.wheelbase_m,
                counter_bits=p.counter_bits,
                integrator=self.integrator,
            )
        )
        if not self.backend.advance_until(self._tracks_our_encoders, timeout_s):
            raise TestkitError(
                f"the firmware's poses do not follow our WHEEL_ENCODERS within "
                f"{timeout_s:g} s (latest ODOM_STATUS: {self.odom_status})"
            )
        acked = self.set_pose(0.0, 0.0, 0.0)
        settled = self.backend.advance_until(lambda: self._at_origin_since(acked), timeout_s)
        if not settled:
            raise TestkitError(
                f"the firmware is not OK at the origin {timeout_s:g} s after "
                f"ODOM_SET_POSE (latest ODOM_STATUS: {self.odom_status})"
            )
        self._t0 = self.backend.now_s()
        self.backend.recorder.reset(self._t0)

    def _tracks_our_encoders(self) -> bool:
        """STATE OK (or DEGRADED for COUNTER_RESET or POSE_UNCERTAIN: our counters restarted, or
        a stall merged steps, and only the pose ``attach`` sets next clears it), and the last
        ``_TRACKING_POSES`` ODOM_POSE_X frames each name one of the encoder frames sent just
        before them: the firmware integrates our counters (after a restart of the sim its E2E
        receiver takes up to 16 frames to accept them again, and it re-primes on the restarted
        counters)."""
        status = self.odom_status
        poses = self.frames("ODOM_POSE_X")[-_TRACKING_POSES:]
        if status is None or len(poses) != _TRACKING_POSES:
            return False
        if status["STATE"] != "OK" and status.get("REASON") not in _POSE_ASKED:
            return False
        encoders = self.frames("WHEEL_ENCODERS")
        for pose in poses:
            t = pose["timestamp_s"]
            recent = {
                e["COUNTER"] for e in encoders if t - _TRACKING_WINDOW_S <= e["timestamp_s"] <= t
            }
            if pose["ENC_COUNTER"] not in recent:
                return False
        return True

    def _at_origin_since(self, t_s: float) -> bool:
        """STATE OK and a pose sent after ``t_s`` at the origin, exactly."""
        status = self.odom_status
        after = any(f["timestamp_s"] > t_s for f in self.frames("ODOM_POSE_Y"))
        ok = bool(status and status["STATE"] == "OK")
        return ok and after and self.pose == Pose(0.0, 0.0, 0.0)

    def close(self) -> None:
        """Release every bus (idempotent)."""
        if not self.closed:
            self.closed = True
            self.backend.close()

    @property
    def buses(self) -> tuple[can.BusABC, ...]:
        """Every bus handle the rig opened (closed by ``close``)."""
        return self.backend.buses()

    # --- time ---------------------------------------------------------------------------------

    @property
    def now_s(self) -> float:
        """Seconds since the recording started."""
        return self.backend.now_s() - self._t0

    def step(self, seconds: float = TICK_S) -> None:
        """Let ``seconds`` pass (computed in lockstep, slept on a real bus)."""
        self.backend.advance(seconds)

    def run_until(self, done: Callable[[], bool], timeout_s: float) -> bool:
        """Let time pass until ``done()`` holds (True) or ``timeout_s`` passed (False)."""
        return self.backend.advance_until(done, timeout_s)

    # --- driving ------------------------------------------------------------------------------

    def drive(self, scenario: str | Scenario, seconds: float | None = None) -> None:
        """Drive the motors open loop with ``scenario`` (a ``sim.scenarios`` name or object) for
        ``seconds`` (default: its own duration, rest included), then stop driving them."""
        if isinstance(scenario, str):
            scenario = get_scenario(scenario, self.robot, self.options.seed)
        self.backend.set_scenario(scenario)
        try:
            self.step(scenario.default_duration_s if seconds is None else seconds)
        finally:
            self.backend.set_scenario(None)

    def goto(
        self,
        x_m: float,
        y_m: float,
        heading_rad: float | None = None,
        *,
        mode: str = "turn_go_turn",
        append: bool = False,
        goal_id: int | None = None,
    ) -> int:
        """Send a NAV_GOAL (REPLACE the path, or ``append`` to it) once the firmware is OK;
        returns its goal id after the firmware ACKed it (``CommandRefused`` on NACK)."""
        if goal_id is None:
            goal_id = self._next_goal_id
        self._next_goal_id = goal_id % 255 + 1
        self._last_goal_id = goal_id
        self.wait_ready()
        self._refused_as_assertion(
            lambda: self.session.goal(
                x_m, y_m, heading_rad, goal_id=goal_id, mode=mode, append=append
            )
        )
        return goal_id

    def path(
        self, waypoints: Iterable[Sequence[float]], *, mode: str = "turn_go_turn"
    ) -> list[int]:
        """Goals through ``(x_m, y_m)`` or ``(x_m, y_m, heading_rad)`` waypoints: the first
        replaces the path, the others are appended; returns their goal ids."""
        ids = []
        for i, point in enumerate(waypoints):
            heading = point[2] if len(point) > 2 else None
            ids.append(self.goto(point[0], point[1], heading, mode=mode, append=i > 0))
        return ids

    def run_until_reached(self, goal_id: int | None = None, timeout_s: float = 60.0) -> None:
        """Let time pass until NAV_STATUS reports ``goal_id`` (default: the last goal sent)
        REACHED; an ``AssertionError`` when it is STOPPED, ABORTED or the time runs out."""
        __tracebackhide__ = True
        if goal_id is None:
            if self._last_goal_id is None:
                raise TestkitError("run_until_reached: no goal was sent (goto or path first)")
            goal_id = self._last_goal_id
        self.backend.advance_until(lambda: self.session.goal_ended(goal_id), timeout_s)
        self.assert_reached(goal_id)

    def _goal_states(self, goal_id: int) -> list[dict[str, Any]]:
        """NAV_STATUS frames of ``goal_id`` heard since its ACK."""
        return self.session.goal_states(goal_id)

    def wait_ready(self, timeout_s: float | None = None) -> None:
        """Let time pass until the latest ODOM_STATUS reports STATE OK (``TestkitError`` if not)."""
        timeout = self.backend.ack_timeout_s if timeout_s is None else timeout_s

        def ready() -> bool:
            status = self.odom_status
            return status is not None and status["STATE"] == "OK"

        if not self.backend.advance_until(ready, timeout):
            raise TestkitError(f"the firmware is not OK (latest ODOM_STATUS: {self.odom_status})")

    def set_pose(self, x_m: float, y_m: float, heading_rad: float) -> float:
        """Overwrite the on-board pose (ODOM_SET_POSE); returns the time of the ACK.

        The analysis does not follow the jump: use it before driving, not in the middle."""
        __tracebackhide__ = True
        ack = self._refused_as_assertion(lambda: self.session.set_pose(x_m, y_m, heading_rad))
        return float(ack["timestamp_s"])

    def command(self, name: str, values: dict[str, Any]) -> float:
        """Send a validated command (``host.protocol.commands``: nav_goal, set_pose, config)
        and wait for the ACK of its last frame; returns the ACK's time (``CommandRefused`` on
        NACK)."""
        __tracebackhide__ = True
        ack = self._refused_as_assertion(lambda: self.session.command(name, values))
        return float(ack["timestamp_s"])

    def _refused_as_assertion(self, send: Callable[[], dict[str, Any]]) -> dict[str, Any]:
        """``send()``'s ACK; a NACK or no answer as ``CommandRefused`` (an ``AssertionError``:
        a test failure), no SecOC freshness as ``TestkitError``."""
        __tracebackhide__ = True
        try:
            return send()
        except CommandNotAcked as exc:
            raise CommandRefused(str(exc)) from None
        except SecocUnsynchronised as exc:
            raise TestkitError(str(exc)) from None

    def send(self, can_id: int, data: bytes) -> None:
        """Send any frame as the HOST (no validation, no E2E: the bytes as given)."""
        self.backend.send(can_id, data)

    # --- reading ------------------------------------------------------------------------------

    def frames(self, name: str, **match: Any) -> list[dict[str, Any]]:
        """Every frame of message ``name`` heard so far that passed its E2E check, decoded by
        cantools (scaled values, choices by name) with ``timestamp_s``; ``match`` keeps the frames
        whose signals have those values, e.g. ``frames("ODOM_STATUS", PAGE="SUMMARY")``."""
        try:
            decoded = self.backend.recorder.decoded(name)
        except UnknownMessageError as exc:
            raise TestkitError(str(exc)) from None
        if not match:
            return decoded
        return [f for f in decoded if all(f.get(k) == v for k, v in match.items())]

    def latest(self, name: str, **match: Any) -> dict[str, Any] | None:
        """The last of ``frames(name, **match)``, None before the first."""
        found = self.frames(name, **match)
        return found[-1] if found else None

    @property
    def nav_status(self) -> dict[str, Any] | None:
        """The latest NAV_STATUS (STATE, GOAL_ID, QUEUE_DEPTH, DISTANCE, HEADING_ERROR)."""
        return self.latest("NAV_STATUS")

    @property
    def odom_status(self) -> dict[str, Any] | None:
        """The latest ODOM_STATUS summary page (STATE, INTEGRATOR, ERROR_MASK, UPTIME)."""
        return self.latest("ODOM_STATUS", PAGE="SUMMARY")

    @property
    def pose(self) -> Pose:
        """The latest on-board pose: ODOM_POSE_X and ODOM_POSE_Y of one encoder frame
        (heading ``TURNS * 2 pi + HEADING``, to 0.1 mm and 2 pi / 65536 rad)."""
        pose = self.backend.recorder.latest_pose()
        if pose is None:
            raise TestkitError("no ODOM_POSE_X/ODOM_POSE_Y pair heard yet: step the rig first")
        return pose

    @property
    def truth(self) -> Pose:
        """The simulated robot's true pose now (float64; heading wrapped to (-pi, pi])."""
        return self.backend.truth()

    @property
    def reference(self) -> Pose:
        """The float64 reference (``host.reference``, same counts, same integrator) at the last
        on-board sample of the analysis."""
        analysis = self.analysis()
        series = analysis.series
        final = analysis.report["final_onboard_pose"]
        heading = final["heading_unwrapped_rad"] - float(series["heading_error_rad"][-1])
        return Pose(float(series["reference_x_m"][-1]), float(series["reference_y_m"][-1]), heading)

    def analysis(self) -> Analysis:
        """``host.analysis.analyze`` over every frame heard (recomputed when frames came in)."""
        heard = len(self.backend.recorder)
        if self._analysis is None or self._analysis[0] != heard:
            frames = self.backend.recorder.arrays()
            self._analysis = (
                heard,
                analyze(frames, self.robot, self.integrator, seed=self.options.seed),
            )
        return self._analysis[1]

    def report(self) -> dict[str, Any]:
        """The analysis report (``onboard_vs_reference``, ``onboard_vs_truth``, ``e2e``, ...)."""
        return self.analysis().report

def make_rig(
    options: RigOptions,
    *,
    bus: dict[str, Any] | None = None,
    encoder: CommandEncoder | None = None,
    attach_timeout_s: float = 30.0,
    ack_timeout_s: float = EXTERNAL_ACK_TIMEOUT_S,
) -> OdocanRig:
    """A rig: lockstep with our firmware (``bus`` None), or around the external firmware on
    ``bus`` (``can.Bus`` keywords), attached within ``attach_timeout_s``, each command's
    ODOM_ACK awaited ``ack_timeout_s`` (wall clock; lockstep waits its simulated second)."""
    if bus is None:
        return OdocanRig(LockstepBackend(options), options, encoder)
    if fault_spec(options.fw_faults) is not None:
        raise TestkitError("fw_faults need our firmware (lockstep): the external one sends alone")
    rig = OdocanRig(ExternalBackend(options, bus, ack_timeout_s), options, encoder)
    try:
        rig.attach(attach_timeout_s)
    except BaseException:
        rig.close()
        raise
    return rig
