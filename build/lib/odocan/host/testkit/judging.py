"""Judging a rig from the bus: on-board pose vs the float64 reference and the truth, goals."""

from __future__ import annotations

import itertools
from typing import Any

from odocan.host.judge.analysis import HEADING_LSB_RAD, POSITION_LSB_M
from odocan.host.protocol.pose import Pose
from odocan.host.testkit.options import RigOptions, TestkitError


class RigAssertions:
    """The judging half of ``OdocanRig``: assertions on its analysis report whose messages carry
    the numbers (``AssertionError``, so pytest shows them as test failures)."""

    options: RigOptions

    @property
    def integrator(self) -> str:
        raise NotImplementedError

    @property
    def now_s(self) -> float:
        raise NotImplementedError

    @property
    def pose(self) -> Pose:
        raise NotImplementedError

    @property
    def nav_status(self) -> dict[str, Any] | None:
        raise NotImplementedError

    def report(self) -> dict[str, Any]:
        raise NotImplementedError

    def _goal_states(self, goal_id: int) -> list[dict[str, Any]]:
        raise NotImplementedError

    def assert_pose_matches_reference(
        self, position_m: float = POSITION_LSB_M, heading_rad: float = HEADING_LSB_RAD
    ) -> None:
        """Every on-board sample within ``position_m`` (distance) and ``heading_rad`` of the
        float64 reference (defaults: one LSB of the pose signals, 0.1 mm and 2 pi / 65536)."""
        __tracebackhide__ = True
        report = self.report()
        errors = report["onboard_vs_reference"]
        where = (
            f"on-board pose vs float64 reference ({self.integrator}, "
            f"{report['samples']['onboard']} samples over {report['sim_seconds']:.2f} s)"
        )
        _check_limits(where, errors, position_m, heading_rad)

    def assert_near_truth(self, position_m: float, heading_rad: float | None = None) -> None:
        """Every on-board sample with a SIM_TRUTH sample of its encoder frame within
        ``position_m`` (distance) and ``heading_rad`` (None: not checked) of the ground truth."""
        __tracebackhide__ = True
        report = self.report()
        errors = report["onboard_vs_truth"]
        compared = report["samples"]["truth_compared"]
        where = (
            f"on-board pose vs ground truth ({compared} samples over "
            f"{errors['distance_travelled_m']:.3f} m, errors {self.options.errors or 'none'})"
        )
        if compared == 0:
            raise AssertionError(f"{where}: no SIM_TRUTH sample to compare with")
        _check_limits(where, errors, position_m, heading_rad)

    def assert_reached(self, goal_id: int) -> None:
        """NAV_STATUS reported ``goal_id`` REACHED (since the firmware ACKed it)."""
        __tracebackhide__ = True
        states = self._goal_states(goal_id)
        if any(f["STATE"] == "REACHED" for f in states):
            return
        if not states:
            latest = self.nav_status
            seen = "none" if latest is None else f"goal {latest['GOAL_ID']} {latest['STATE']}"
            raise AssertionError(
                f"goal {goal_id} not reached at t = {self.now_s:.2f} s: no NAV_STATUS for it "
                f"(latest NAV_STATUS: {seen})"
            )
        last = states[-1]
        path = " -> ".join(s for s, _ in itertools.groupby(f["STATE"] for f in states))
        raise AssertionError(
            f"goal {goal_id} not reached at t = {self.now_s:.2f} s: {last['STATE']}, "
            f"{last['DISTANCE']:.3f} m and {last['HEADING_ERROR']:.4f} rad to go, "
            f"pose {self._pose_text()} (states: {path})"
        )

    def _pose_text(self) -> str:
        try:
            x, y, heading = self.pose
        except TestkitError:
            return "unknown"
        return f"({x:.4f} m, {y:.4f} m, {heading:.4f} rad)"



def _fmt(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.3g}"


def _check_limits(
    where: str, errors: dict[str, Any], position_m: float, heading_rad: float | None
) -> None:
    """An AssertionError naming every limit exceeded, with the numbers."""
    __tracebackhide__ = True
    failures = []
    position = errors["max_position_error_m"]
    if position is None:
        raise AssertionError(f"{where}: no sample to compare")
    if position > position_m:
        failures.append(
            f"max position error {_fmt(position)} m > {_fmt(position_m)} m "
            f"(final {_fmt(errors['final_position_error_m'])} m)"
        )
    heading = errors["max_heading_error_rad"]
    if heading_rad is not None and heading > heading_rad:
        failures.append(
            f"max heading error {_fmt(heading)} rad > {_fmt(heading_rad)} rad "
            f"(final {_fmt(errors['final_heading_error_rad'])} rad)"
        )
    if failures:
        raise AssertionError(f"{where}: " + "; ".join(failures))


