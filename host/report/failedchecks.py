"""The checks a FAIL line names, in words (``host.report.summary``): ODOM_TWIST's speeds and
DISTANCE, and the poses sent first after a silence (``host.judge.stallfirst``)."""

from __future__ import annotations

from typing import Any


def twist_failures(twist: dict[str, Any], distance: dict[str, Any]) -> list[str]:
    """The ODOM_TWIST criteria not met (speeds, DISTANCE), in words."""
    failed = []
    if not twist["passed"]:  # 0.18 mm/s was 0.000 m/s
        failed.append("ODOM_TWIST outside the reference's speeds by up to "
                      f"{twist['max_linear_excess_mps'] * 1e3:.3g} mm/s, "
                      f"{twist['max_angular_excess_rad_s'] * 1e3:.3g} mrad/s")
    if not distance["passed"]:
        failed.append("ODOM_TWIST DISTANCE off the reference's path length by "
                      f"{distance['max_excess_m'] * 1e3:.3f} mm beyond its tolerance")
    return failed


def first_pose_failures(report: dict[str, Any]) -> list[str]:
    """The poses sent first after a silence that failed (``host.judge.stallfirst``), in words:
    a FAIL line names the check that failed (a FAIL on this alone said only the pose criterion
    with no "not met")."""
    first = report.get("stall_first_pose") or {}
    if first.get("passed", True):
        return []
    failed = []
    if max(first.get("max_position_beyond_m") or 0.0, first.get("max_heading_beyond_rad") or 0.0):
        failed.append(f"a pose sent first after a silence off the poses around it by "
                      f"{(first['max_position_beyond_m'] or 0.0) * 1e3:.4g} mm, "
                      f"{max(first['max_heading_beyond_rad'] or 0.0, 0.0) * 1e3:.4g} mrad "
                      f"beyond the tolerance at {first['worst_at_s']:.3f} s")
    if (first.get("max_resume_beyond_m") or 0.0) > 0:
        failed.append(f"the pose at {first['resume_at_s']:.3f} s "
                      f"{first['max_resume_beyond_m'] * 1e3:.4g} mm beyond any the firmware can "
                      "resume at after its stall")
    return failed
