"""The Python firmware's odometry steps, watched and integrated again in plain float64 (issue #11:
who is wrong when a judge FAILs a drive, the firmware or the judge).

``watched(robot)`` monkeypatches ``firmware.odometry.Odometry.step_deltas`` and ``set_pose`` for
the duration of a ``with`` block: each step the firmware integrated is integrated again here (the
exact arc) from the pose the firmware had before it, and the RAM pose after the step is compared
with it (``Watch.worst_m``, ``Watch.worst_rad``). A firmware within 1/1000 LSB of that on every
step integrated the frames it took correctly; a judge that FAILs it models those frames wrong.
Moved here from ``tests/test_combo_faults.py`` to serve other robots' drives too."""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

from odocan.firmware import odometry as fo
from odocan.sim.robot import RobotProfile, load

POSITION_LSB_M, HEADING_LSB_RAD = 1e-4, 2 * math.pi / 65536


class Watch:
    """The firmware's steps integrated again in float64 from the pose it had (per odometry)."""

    def __init__(self, robot: RobotProfile) -> None:
        p = robot.firmware_params()
        self.m_left = 2 * math.pi * p["wheel_radius_left_nm"] * 1e-9 / p["counts_per_rev"]
        self.m_right = 2 * math.pi * p["wheel_radius_right_nm"] * 1e-9 / p["counts_per_rev"]
        self.b = p["wheelbase_nm"] * 1e-9
        self.poses: dict[int, list[float]] = {}
        self.steps = 0
        self.worst_m = self.worst_rad = 0.0

    @staticmethod
    def ram(odo: fo.Odometry) -> list[float]:
        return [odo.x_q40_m / 2**40, odo.y_q40_m / 2**40,
                (odo.heading_bam64 / 2**64 + odo.heading_turns) * 2 * math.pi]

    def step(self, odo: fo.Odometry, d_left: int, d_right: int) -> None:
        """After ``odo`` integrated (d_left, d_right): the same step in float64, compared."""
        s = self.poses[id(odo)]
        ds = 0.5 * (d_left * self.m_left + d_right * self.m_right)
        dth = (d_right * self.m_right - d_left * self.m_left) / self.b
        old, new = s[2], s[2] + dth
        if abs(dth) < 1e-6:
            factor = 1 - dth * dth / 24
            s[0] += ds * factor * math.cos(old + dth / 2)
            s[1] += ds * factor * math.sin(old + dth / 2)
        else:
            s[0] += ds / dth * (math.sin(new) - math.sin(old))
            s[1] -= ds / dth * (math.cos(new) - math.cos(old))
        s[2] = new
        x, y, h = self.ram(odo)
        self.steps += 1
        self.worst_m = max(self.worst_m, math.hypot(x - s[0], y - s[1]))
        self.worst_rad = max(self.worst_rad, abs((h - new + math.pi) % (2 * math.pi) - math.pi))

    def within_a_thousandth_lsb(self) -> bool:
        """Every step within 1/1000 of the pose signals' LSB (position and heading)."""
        return (self.worst_m <= POSITION_LSB_M / 1000
                and self.worst_rad <= HEADING_LSB_RAD / 1000)


@contextmanager
def watched(robot: RobotProfile | str = "kobuki") -> Iterator[Watch]:
    """The firmware's ``Odometry`` watched (``Watch``) inside the block."""
    watch = Watch(load(robot) if isinstance(robot, str) else robot)
    step, set_pose = fo.Odometry.step_deltas, fo.Odometry.set_pose

    def watched_step(odo: fo.Odometry, d_left: int, d_right: int) -> None:
        watch.poses.setdefault(id(odo), watch.ram(odo))
        step(odo, d_left, d_right)
        watch.step(odo, d_left, d_right)

    def watched_set_pose(odo: fo.Odometry, x: int, y: int, heading: int) -> None:
        set_pose(odo, x, y, heading)
        watch.poses[id(odo)] = watch.ram(odo)

    with pytest.MonkeyPatch.context() as monkeypatch:
        monkeypatch.setattr(fo.Odometry, "step_deltas", watched_step)
        monkeypatch.setattr(fo.Odometry, "set_pose", watched_set_pose)
        yield watch
