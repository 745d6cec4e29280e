"""One judge of ODOM_TWIST's speeds (issue #11, points 3 and 6): ``analyze``, the monitor and the
MQTT bridge fed the same frames give LINEAR_VEL and ANGULAR_VEL the same verdict, on the same
number of frames, with the same largest excesses (1e-12).

The live judges judged DISTANCE only: a firmware whose LINEAR_VEL was 5 % high, or whose
twist after a gap took the 4-bit COUNTER's dt (17 x the speed after 16 lost frames), FAILed in
analyze and was OK in the monitor and the bridge. The wrong firmwares are checked wrong
independently: their frames against the correct firmware's on the same drive, decoded with
cantools (the drive is deterministic: only the patched signal differs).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import can
import pytest

from odocan.firmware.ecu import OdomEcu
from odocan.host.io.logs import parse_candump
from odocan.host.judge.analysis import analyze
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim import robot
from odocan.sim.faults import FaultSpec
from odocan.sim.rig import LockstepRig, RigConfig
from tests.dbc_typed import numbers
from tests.test_health_twist import _old_dt
from tests.test_one_judge import _candump
from tests.test_twist_resends import _stall_drive

PMIR = robot.load("pmir")
Patch = Callable[[OdomEcu], None]


def _drive(scenario: str, seconds: float, faults: str | None = None,
           patch: Patch | None = None) -> list[can.Message]:
    messages: list[can.Message] = []

    class Keep(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            messages.append(msg)

    config = RigConfig(PMIR, "exact", scenario, 1, duration_s=seconds,
                       faults=FaultSpec.parse(faults) if faults else None,
                       channel=f"test-one-judge-twist-{scenario}-{faults}")
    with LockstepRig(config, [Keep()]) as rig:
        if patch is not None:
            patch(rig.board.ecu)
        rig.run()
    return messages


def _scaled(linear: float = 1.0, angular_lsb: int = 0) -> Patch:
    """A firmware whose LINEAR_VEL is ``linear`` times the speed, ANGULAR_VEL off by
    ``angular_lsb`` mrad/s."""
    def patch(ecu: OdomEcu) -> None:
        twist = ecu.twist
        update = twist.update

        def wrong(periods: int) -> None:
            update(periods)
            twist.linear_mm_s = round(twist.linear_mm_s * linear)
            twist.angular_mrad_s += angular_lsb

        twist.update = wrong  # type: ignore[method-assign]
    return patch


def _three(messages: list[can.Message]) -> tuple[dict[str, Any], BusMonitor, RobotTelemetry]:
    result = analyze(parse_candump(_candump(messages)), PMIR)
    monitor = BusMonitor(PMIR)
    bridge = RobotTelemetry("r", Geometry.of(PMIR), result.report["integrator"],
                            counter_bits=PMIR.counter_bits, publish_hz=10)
    for msg in messages:
        monitor.feed(msg, now_s=msg.timestamp)
        bridge.feed(msg)
    twist: dict[str, Any] = result.report["onboard_twist_vs_reference"]
    return twist, monitor, bridge


def _agree(messages: list[can.Message]) -> tuple[dict[str, Any], BusMonitor, RobotTelemetry]:
    """The three on one log: the same twist verdict, samples and excesses; the monitor's state
    and the bridge's ``status`` say it."""
    offline, monitor, bridge = _three(messages)
    for live in (monitor.snapshot(messages[-1].timestamp)["twist"],
                 bridge.status()[1]["twist"]):
        assert live["samples"] == offline["samples"]
        assert live["max_linear_excess_mps"] == pytest.approx(
            offline["max_linear_excess_mps"], abs=1e-12)
        assert live["max_angular_excess_rad_s"] == pytest.approx(
            offline["max_angular_excess_rad_s"], abs=1e-12)
        assert live["passed"] == offline["passed"]
    state = monitor.health(messages[-1].timestamp)["state"]
    if not offline["passed"] and monitor.distance.as_dict()["passed"]:
        assert state == "TWIST WRONG"
    return offline, monitor, bridge


def _twists(messages: list[can.Message]) -> list[tuple[int, int]]:
    """(LINEAR_VEL, ANGULAR_VEL) raw of every ODOM_TWIST, decoded with cantools."""
    from odocan.sim.contract import database
    db = database()
    out = []
    for m in messages:
        if m.arbitration_id == 0x202:
            s = numbers(db, 0x202, bytes(m.data), scaling=False)
            out.append((int(s["LINEAR_VEL"]), int(s["ANGULAR_VEL"])))
    return out


@pytest.fixture(scope="module")
def curvy() -> list[can.Message]:
    return _drive("random", 12.0)


def test_a_correct_firmware_passes_all_three(curvy: list[can.Message]) -> None:
    offline, monitor, _ = _agree(curvy)
    assert offline["passed"]
    assert offline["samples"] > 500
    assert monitor.health(curvy[-1].timestamp)["state"] == "OK"


@pytest.mark.parametrize(("linear", "angular_lsb", "fails"),
                         [(1.01, 0, False), (1.05, 0, True), (1.0, 4, True)])
def test_a_wrong_twist_gets_one_verdict(curvy: list[can.Message], linear: float,
                                         angular_lsb: int, fails: bool) -> None:
    """LINEAR_VEL 1 % high (within the band's 2 %: PASS everywhere), 5 % high and ANGULAR_VEL
    4 mrad/s off (FAIL everywhere, by the same excess)."""
    messages = _drive("random", 12.0, patch=_scaled(linear, angular_lsb))
    right, wrong = _twists(curvy), _twists(messages)
    assert len(right) == len(wrong)
    offsets = [w[1] - r[1] for r, w in zip(right, wrong, strict=True)]
    assert offsets[1:] == [angular_lsb] * (len(offsets) - 1)  # (the first: before any update)
    assert max(abs(w[0] - r[0] * linear) for r, w in zip(right, wrong, strict=True)) <= 0.5
    offline, monitor, bridge = _agree(messages)
    assert offline["passed"] is not fails
    if fails:
        assert monitor.twist.verdict()
        assert bridge.status()[1]["twist"]["passed"] is False


@pytest.mark.parametrize(("busoff_s", "shows"), [(0.17, True), (0.32, False), (1.01, True)])
def test_the_three_agree_after_a_gap(busoff_s: float, shows: bool) -> None:
    """The correct firmware's speeds after a gap of 16, 31, 100 periods PASS everywhere; the
    twist of the 4-bit COUNTER's dt FAILs everywhere alike where its frames show it (``shows``:
    3.2 and 7.4 m/s for a 0.5 m/s robot; after 31 periods 0.57 m/s, within the 5 m/s^2 a
    31-period step allows: PASS everywhere alike)."""
    faults = f"busoff=3:{busoff_s}"
    offline, _, _ = _agree(_drive("straight", 6.0, faults))
    assert offline["passed"]
    messages = _drive("straight", 6.0, faults, _old_dt)
    assert (max(v for v, _ in _twists(messages)) > 2500) is shows  # mm/s
    offline, monitor, _ = _agree(messages)
    assert offline["passed"] is not shows
    if shows:
        assert offline["max_linear_excess_mps"] > 1.0
    if busoff_s > 1.0:  # the 100-period step's path is unknowable: latched until a set-pose;
        # the monitor says TWIST WRONG (``_agree``) and why, the firmware's DEGRADED with it
        why = monitor.health(messages[-1].timestamp)["why"]
        assert why[-1].startswith("firmware reports DEGRADED (POSE_UNCERTAIN")


def test_the_three_agree_on_a_carried_update() -> None:
    """The stall drive of test_twist_resends: the update from the carried steps under the
    ENC_COUNTER sent before PASSes live too."""
    offline, _, _ = _agree(_stall_drive())
    assert offline["passed"]


class _Replay(can.BusABC):
    """A bus that hears ``messages``, then gets Ctrl-C."""

    def __init__(self, messages: list[can.Message]) -> None:
        self.left = list(reversed(messages))
        super().__init__(channel="replay-then-ctrl-c")

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if not self.left:
            raise KeyboardInterrupt
        return self.left.pop(), False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        raise NotImplementedError


def test_the_watch_exits_1_on_a_wrong_twist(monkeypatch: pytest.MonkeyPatch,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    """``odocan monitor`` on the correct firmware's drive: exit 0; LINEAR_VEL 5 % high: the
    FAIL line and exit 1."""
    from odocan.host.cli.app import main
    from odocan.host.cli.subparsers import monitor as monitor_cmd

    for linear, code in ((1.0, 0), (1.05, 1)):
        messages = _drive("random", 6.0, patch=_scaled(linear))
        monkeypatch.setattr(monitor_cmd, "open_bus", lambda args, m=messages: _Replay(m))
        assert main(["monitor", "-i", "virtual", "--robot", "pmir", "--json"]) == code
        err = capsys.readouterr().err
        said = "monitor: FAIL: ODOM_TWIST outside the reference's speeds by up to" in err
        assert said is bool(code), err
