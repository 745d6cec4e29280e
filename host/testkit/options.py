"""What a rig is made of, and the errors the pytest kit raises."""

from __future__ import annotations

from dataclasses import dataclass

from odocan.sim.errors import ErrorModel
from odocan.sim.errors import parse as parse_errors
from odocan.sim.exceptions import OdocanError
from odocan.sim.faults import FaultSpec
from odocan.sim.robot import RobotProfile
from odocan.sim.robot import load as load_robot


class TestkitError(OdocanError):
    """The rig cannot do what was asked (no frame yet, a firmware that does not answer, ...)."""

    __test__ = False  # not a test class, whatever pytest's collection rules say


class CommandRefused(AssertionError):
    """The firmware answered a command with ODOM_ACK NACK (or not at all)."""


@dataclass(frozen=True)
class RigOptions:
    """What a rig is made of (strings as on the command line: ``errors="ed=1.002"``)."""

    robot: str = "pmir"
    integrator: str = "exact"
    errors: str = ""
    faults: str = ""
    fw_faults: str = ""
    seed: int = 0
    firmware: str = "python"  # lockstep only: "python" (firmware/) or "c" (firmware/c)
    secoc_key: str = ""  # SecOC key file: our firmware provisioned with it, commands signed

    def profile(self) -> RobotProfile:
        """The robot profile (a name or a TOML path)."""
        return load_robot(self.robot)

    def error_model(self) -> ErrorModel:
        """The simulated robot's real errors."""
        return parse_errors(self.errors)


def fault_spec(text: str, seed: int = 0) -> FaultSpec | None:
    """The spec of ``text`` (None when it injects nothing); its seed, unless the text sets
    ``seed=``: ``seed`` (the rig's, as ``odocan run --seed`` gives its faults)."""
    spec = FaultSpec.parse(text, seed=seed)
    return spec if spec.active else None


