"""``--firmware auto|python|c`` of ``odocan run``, ``odocan firmware`` and ``odocan fleet``.

``auto``, the default of all three: the C port (``firmware/c`` through ``sim.cboard``) when its
library builds and loads (and takes a SecOC key when one is given), else the Python firmware,
and why. The C port is bit-exact with the Python firmware (the same log, byte for byte:
tests/test_c_rig.py) and about twice as fast in the lockstep rig (docs/benchmarks.md: the
360x target of ``odocan run --duration 3600`` is met with C only); its fleet step costs a third
less CPU (bench/fleet_step.py). A firmware asked by name is taken as asked: ``--firmware c``
that cannot build stays one ``error:`` line. The APIs (``sim.rig.RigConfig``, the fleet's
config, the pytest plugin) keep ``python`` as their default: only the CLI chooses.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from odocan.firmware.config import RobotParams
from odocan.sim.cboard import FIRMWARES, FirmwareBuildError, board_maker
from odocan.sim.exceptions import ConfigurationError

AUTO_FIRMWARE = "auto"  # --firmware's default: c when its library builds and loads, else python
FIRMWARE_CHOICES = (AUTO_FIRMWARE, *FIRMWARES)
AUTO_TOOK_C = "it built and loaded; --firmware python for the Python one"


@dataclass(frozen=True)
class FirmwareChoice:
    """The firmware that runs (``python`` or ``c``), whether ``auto`` chose it, and why."""

    firmware: str
    auto: bool = False
    why: str = ""  # auto only: why this one

    @property
    def said(self) -> str:
        """The start line's words (``odocan fleet``): ``firmware c (auto: it built ...)``."""
        return f"firmware {self.firmware}" + (f" (auto: {self.why})" if self.auto else "")

    @property
    def words(self) -> str:
        """The summary's words (``odocan run``'s title, ``odocan firmware``'s last line):
        ``c firmware (auto: it built and loaded; ...)``, ``python firmware``."""
        return f"{self.firmware} firmware" + (f" (auto: {self.why})" if self.auto else "")

    def as_dict(self) -> dict[str, Any]:
        """The report's ``inputs.firmware``: what ran, whether ``auto`` chose it, and why."""
        return {"name": self.firmware, "auto": self.auto, "why": self.why}


def resolve_firmware(asked: str, secoc: bool, params: RobotParams) -> FirmwareChoice:
    """``--firmware``: python or c as asked; ``auto``: c when its library builds and loads (and
    takes a SecOC key when ``secoc``, and runs ``params``' robot: a library older than ABI 3
    only runs one bounded at 4 m/s), else python with the reason the C firmware is
    unavailable."""
    if asked != AUTO_FIRMWARE:
        return FirmwareChoice(asked)
    try:
        board_maker("c", secoc=secoc, params=params)
    except (FirmwareBuildError, ConfigurationError) as exc:
        return FirmwareChoice("python", True, f"the C firmware is unavailable: {exc}")
    return FirmwareChoice("c", True, AUTO_TOOK_C)
