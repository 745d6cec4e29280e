"""The odocan pytest plugin: the ``odocan_rig`` fixture, its options and its marker.

Installed with the package (entry point ``pytest11``), so a test only asks for the fixture::

    def test_goal(odocan_rig):
        rig = odocan_rig(robot="pmir", integrator="exact", errors="ed=1.002")
        goal = rig.goto(1.0, 0.5)
        rig.run_until_reached(goal, timeout_s=30)
        rig.assert_pose_matches_reference(position_m=1e-4)

``odocan_rig`` is a factory: each call builds an ``host.testkit.OdocanRig`` (keywords ``robot``,
``integrator``, ``errors``, ``faults``, ``fw_faults``, ``seed``) and every rig is closed, its buses
shut down, when the test ends, pass or fail. Defaults, weakest first: the ini options
``odocan_robot``, ``odocan_integrator``, ``odocan_errors``, ``odocan_faults``, ``odocan_seed``;
then a test's ``@pytest.mark.odocan(robot=..., ...)``; then the factory's keywords.

**Another firmware**: ``--odocan-bus "interface=udp_multicast,channel=239.74.163.9,hop_limit=0"``
(or the ini option ``odocan_bus``; python-can ``can.Bus`` keywords) runs the same tests against
whatever firmware is on that bus: the fixture then does not start ours; it plays the motor
controller, the ground truth and the scenario driver in real time there and judges what the
firmware sends (``host.testkit``). ``odocan_attach_timeout`` (s, default 30) bounds the wait for
the firmware's first ODOM_STATUS, ``odocan_ack_timeout`` (s, default 3) each command's ODOM_ACK.

**Our C firmware**: ``--odocan-firmware c`` (or the ini option ``odocan_firmware``) runs the
lockstep rigs on the C port (``firmware/c``, built with make on first use, ``sim.cboard``).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import ExitStack
from typing import TYPE_CHECKING, Any, Protocol

import pytest

if TYPE_CHECKING:  # the rig's modules (cantools, numpy, the sim) load with the first rig only
    from odocan.host.protocol.commands import CommandEncoder
    from odocan.host.testkit.rig import OdocanRig

_INI = {
    "odocan_robot": ("robot profile name or TOML path of odocan_rig", "pmir"),
    "odocan_integrator": ("integrator of odocan_rig: euler, rk2 or exact", "exact"),
    "odocan_errors": ("the simulated robot's real errors, e.g. ed=1.002,eb=1.01,slip=0.01", ""),
    "odocan_faults": ("faults on what MOTOR_CTRL and SIM send, e.g. drop=0.01,seed=3", ""),
    "odocan_seed": ("seed of odocan_rig's vehicle, scenarios and faults (unless seed=)", "0"),
    "odocan_secoc_key": (
        "SecOC key file (16 raw bytes or 32 hex digits): our firmware is provisioned with it "
        "and every command is signed (docs/secoc.md; none: no SecOC)",
        "",
    ),
    "odocan_bus": ("can.Bus keywords of a bus with an external firmware (none: lockstep)", ""),
    "odocan_attach_timeout": ("seconds to wait for an external firmware to answer", "30"),
    "odocan_ack_timeout": ("seconds an external firmware has to acknowledge a command", "3"),
    "odocan_firmware": ("our firmware in lockstep: python or c (firmware/c)", "python"),
}
_FIRMWARES = ("python", "c")  # sim.cboard.FIRMWARES, without importing the sim here
_KEYS = ("robot", "integrator", "errors", "faults", "fw_faults", "seed", "secoc_key")
_ENCODER = pytest.StashKey["CommandEncoder"]()


class RigFactory(Protocol):
    """The ``odocan_rig`` fixture: builds a rig; keywords override the test's defaults."""

    def __call__(
        self,
        *,
        robot: str | None = None,
        integrator: str | None = None,
        errors: str | None = None,
        faults: str | None = None,
        fw_faults: str | None = None,
        seed: int | None = None,
        secoc_key: str | None = None,
    ) -> OdocanRig:
        """A new rig (closed at the end of the test)."""
        ...


def pytest_addoption(parser: pytest.Parser) -> None:
    """``--odocan-bus`` and the ini defaults."""
    group = parser.getgroup("odocan", "odocan firmware rig (odocan_rig fixture)")
    group.addoption(
        "--odocan-bus",
        metavar="KEY=VALUE,...",
        default=None,
        help="run odocan_rig against the external firmware on this python-can bus, e.g. "
        "interface=udp_multicast,channel=239.74.163.9,hop_limit=0 (default: our firmware in "
        "lockstep)",
    )
    group.addoption(
        "--odocan-firmware",
        choices=_FIRMWARES,
        default=None,
        help="the firmware of the lockstep rigs: python (firmware/) or c (firmware/c, built with "
        "make on first use) (default: ini odocan_firmware, else python)",
    )
    for name, (text, default) in _INI.items():
        parser.addini(name, text, default=default)


def pytest_configure(config: pytest.Config) -> None:
    """Register the ``odocan`` marker."""
    config.addinivalue_line(
        "markers",
        "odocan(robot=, integrator=, errors=, faults=, fw_faults=, seed=, secoc_key=): defaults "
        "of the "
        "odocan_rig fixture for this test",
    )


def bus_kwargs(config: pytest.Config) -> dict[str, Any] | None:
    """The external bus (``--odocan-bus``, else ini ``odocan_bus``), None for lockstep."""
    from odocan.host.testkit.backends import parse_bus_spec

    text = config.getoption("--odocan-bus") or str(config.getini("odocan_bus"))
    return parse_bus_spec(text) if text.strip() else None


def firmware_kind(config: pytest.Config) -> str:
    """Our firmware for the lockstep rigs (``--odocan-firmware``, else ini ``odocan_firmware``)."""
    kind = config.getoption("--odocan-firmware") or str(config.getini("odocan_firmware")).strip()
    if kind not in _FIRMWARES:
        raise pytest.UsageError(f"odocan_firmware must be one of {', '.join(_FIRMWARES)}: {kind!r}")
    return kind


def pytest_report_header(config: pytest.Config) -> str:
    """One header line: which firmware the rigs put under test."""
    text = config.getoption("--odocan-bus") or str(config.getini("odocan_bus"))
    if text.strip():
        return f"odocan: external firmware on {text.strip()} (real time)"
    if firmware_kind(config) == "c":
        return "odocan: our C firmware (firmware/c) in lockstep (simulated time)"
    return "odocan: our firmware in lockstep (simulated time)"


def _defaults(request: pytest.FixtureRequest) -> dict[str, Any]:
    """The ini defaults overridden by the test's ``odocan`` markers (closest last)."""
    config = request.config
    values: dict[str, Any] = {
        key: str(config.getini(f"odocan_{key}")) for key in _KEYS if key != "fw_faults"
    }
    values["seed"] = int(values["seed"])
    for marker in reversed(list(request.node.iter_markers("odocan"))):
        unknown = set(marker.kwargs) - set(_KEYS)
        if unknown or marker.args:
            raise pytest.UsageError(
                f"@pytest.mark.odocan takes keywords {', '.join(_KEYS)}; got "
                f"{', '.join(sorted(unknown)) or marker.args}"
            )
        values.update(marker.kwargs)
    return values


def _encoder(config: pytest.Config) -> CommandEncoder:
    """One HOST command encoder per session: an external firmware lives on between tests and
    its E2E receivers expect the host's counters to go on."""
    from odocan.host.protocol.commands import CommandEncoder

    if _ENCODER not in config.stash:
        config.stash[_ENCODER] = CommandEncoder()
    return config.stash[_ENCODER]


@pytest.fixture
def odocan_rig(request: pytest.FixtureRequest) -> Iterator[RigFactory]:
    """A factory of rigs (``host.testkit.OdocanRig``), each closed when the test ends."""
    from odocan.host.testkit.options import RigOptions
    from odocan.host.testkit.rig import make_rig

    defaults = _defaults(request)
    bus = bus_kwargs(request.config)
    firmware = firmware_kind(request.config)
    if bus is not None and firmware != "python":
        raise pytest.UsageError(
            "--odocan-firmware chooses our firmware in lockstep; with --odocan-bus the firmware "
            "under test is the one on that bus (run it with odocan firmware --firmware c)"
        )
    timeout_s = float(str(request.config.getini("odocan_attach_timeout")))
    ack_timeout_s = float(str(request.config.getini("odocan_ack_timeout")))
    rigs: list[OdocanRig] = []

    def factory(**overrides: Any) -> OdocanRig:
        unknown = set(overrides) - set(_KEYS)
        if unknown:
            raise TypeError(f"odocan_rig() got unknown keywords: {', '.join(sorted(unknown))}")
        chosen = {**defaults, **{k: v for k, v in overrides.items() if v is not None}}
        if bus is not None and any(not rig.closed for rig in rigs):
            raise pytest.UsageError("one odocan rig at a time on an external firmware's bus")
        encoder = None if bus is None else _encoder(request.config)
        options = RigOptions(**chosen, firmware=firmware)
        rig = make_rig(options, bus=bus, encoder=encoder, attach_timeout_s=timeout_s,
                       ack_timeout_s=ack_timeout_s)
        rigs.append(rig)
        return rig

    with ExitStack() as stack:
        yield factory
        for rig in rigs:
            stack.callback(rig.close)  # last in, first closed; each one even if another fails
