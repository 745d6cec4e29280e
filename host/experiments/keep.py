"""A calibration the user can keep: the corrected profile as TOML, and ROS 2's multipliers.

``corrected_profile`` is the nominal profile with the corrected radii and wheelbase, each rounded
to the whole nanometre the firmware is configured with (what ``calibrate`` sent over CAN), so the
file written by ``sim.robot.to_toml`` and read back by ``--robot PATH`` configures the very same
firmware. ``ros2_multipliers`` says the same in ROS 2 ``diff_drive_controller`` terms: its
``wheel_separation_multiplier``, ``left_wheel_radius_multiplier`` and
``right_wheel_radius_multiplier`` scale its ``wheel_separation`` / ``wheel_radius``
parameters, so each is corrected / nominal. The controller has ONE ``wheel_radius`` for both
wheels: the multipliers are given against the mean of the nominal radii, and the YAML carries
that ``wheel_radius`` and the nominal ``wheel_separation`` they refer to (a robot with unequal
nominal radii is then configured right; with equal ones the multipliers are corrected / nominal
per side, as before).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from odocan.host.experiments.umbmark import Correction
from odocan.host.outputs import check_writable, write_text
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.robot import NM_PER_M, RobotProfile, to_toml

ROS2_KEYS = (
    "wheel_separation",
    "wheel_radius",
    "wheel_separation_multiplier",
    "left_wheel_radius_multiplier",
    "right_wheel_radius_multiplier",
)


def _on_nm_grid(length_m: float) -> float:
    """The length rounded to whole nanometres, as the double nearest that integer (m)."""
    return round(length_m * NM_PER_M) / NM_PER_M


def corrected_profile(nominal: RobotProfile, corrected: Correction) -> RobotProfile:
    """``nominal`` with the corrected geometry (nm grid), named ``<name>-calibrated``."""
    return replace(
        nominal,
        name=f"{nominal.name}-calibrated",
        wheel_radius_left_m=_on_nm_grid(corrected.wheel_radius_left_m),
        wheel_radius_right_m=_on_nm_grid(corrected.wheel_radius_right_m),
        wheelbase_m=_on_nm_grid(corrected.wheelbase_m),
    )


def ros2_multipliers(nominal: RobotProfile, corrected: RobotProfile) -> dict[str, float]:
    """diff_drive_controller's parameters: the nominal ``wheel_separation`` and the one
    ``wheel_radius`` (the mean of the nominal radii), in metres, and the multipliers
    (dimensionless) that scale them to the corrected geometry."""
    radius_m = (nominal.wheel_radius_left_m + nominal.wheel_radius_right_m) / 2
    return {
        "wheel_separation": nominal.wheelbase_m,
        "wheel_radius": radius_m,
        "wheel_separation_multiplier": corrected.wheelbase_m / nominal.wheelbase_m,
        "left_wheel_radius_multiplier": corrected.wheel_radius_left_m / radius_m,
        "right_wheel_radius_multiplier": corrected.wheel_radius_right_m / radius_m,
    }


def ros2_yaml(multipliers: dict[str, float]) -> str:
    """The multipliers as the ``ros__parameters`` lines of a controller YAML file."""
    lines = [f"    {key}: {multipliers[key]:.9f}" for key in ROS2_KEYS]
    return "diff_drive_controller:\n  ros__parameters:\n" + "\n".join(lines) + "\n"


def check_robot_path(path: Path | None) -> None:
    """Refuse a ``--write-robot`` that ``--robot`` could not load back (not ``.toml``) or that
    cannot be written, before the runs."""
    if path is None:
        return
    if path.suffix.lower() != ".toml":
        raise ConfigurationError(
            f"--write-robot {path}: must end in .toml (so that --robot {path} reads it as a file)"
        )
    check_writable(path, "--write-robot")


def write_robot(path: Path, profile: RobotProfile) -> None:
    """Write ``profile`` as TOML to ``path``; an I/O error names the path."""
    write_text(path, to_toml(profile), "--write-robot")
