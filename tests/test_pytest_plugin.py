"""The pytest plugin (``host.pytest_plugin``) used the way a user uses it: test files run by
``pytester``, in lockstep and against an external firmware (our own, as a separate process on
``udp_multicast``), with assertions that fail and say why, the options, and the teardown.
"""

from __future__ import annotations

import secrets
import signal
import socket
import subprocess
import sys
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any

import can
import pytest

from odocan.host.testkit.backends import parse_bus_spec
from odocan.sim.exceptions import BusSetupError

pytest_plugins = ["pytester"]

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "test_my_robot.py"


def plugin_args() -> list[str]:
    """``-p odocan.host.testkit.plugin`` unless the package's pytest11 entry point loads it."""
    plugin = "odocan.host.testkit.plugin"
    installed = any(ep.value == plugin for ep in entry_points(group="pytest11"))
    return [] if installed else ["-p", plugin]


def run(pytester: pytest.Pytester, *args: str) -> pytest.RunResult:
    return pytester.runpytest(*plugin_args(), "-p", "no:cacheprovider", *args)


# --- lockstep -----------------------------------------------------------------------------------


def test_the_readme_example_passes_in_lockstep(pytester: pytest.Pytester) -> None:
    pytester.makepyfile(test_users_robot=EXAMPLE.read_text())
    result = run(pytester, "-v")
    result.assert_outcomes(passed=2)
    result.stdout.fnmatch_lines(["odocan: our firmware in lockstep (simulated time)"])


FAILING = """
import math

def test_reference_bound_below_the_rounding(odocan_rig):
    rig = odocan_rig()
    rig.drive("circle", seconds=2.0)
    rig.assert_pose_matches_reference(position_m=1e-9, heading_rad=1.0)

def test_truth_bound_below_the_drift(odocan_rig):
    rig = odocan_rig(errors="ed=1.01")
    rig.drive("straight")
    rig.assert_near_truth(position_m=1e-3, heading_rad=1e-3)

def test_goal_not_reached_in_time(odocan_rig):
    rig = odocan_rig()
    goal = rig.goto(2.0, 2.0)
    rig.run_until_reached(goal, timeout_s=0.5)

def test_a_goal_never_sent(odocan_rig):
    rig = odocan_rig()
    rig.step(1.0)
    rig.assert_reached(9)
"""


def test_failing_assertions_carry_the_numbers(pytester: pytest.Pytester) -> None:
    pytester.makepyfile(test_fails=FAILING)
    result = run(pytester)
    result.assert_outcomes(failed=4)
    result.stdout.fnmatch_lines_random([
        "*AssertionError: on-board pose vs float64 reference (exact, * samples over *s): "
        "max position error * m > 1e-09 m (final * m)",
        "*AssertionError: on-board pose vs ground truth (* samples over 2.* m, errors ed=1.01): "
        "max position error * m > 0.001 m (final * m); max heading error * rad > 0.001 rad*",
        "*AssertionError: goal 1 not reached at t = 0.5* s: TURNING, 2.8* m and * rad to go, "
        "pose (* m, * m, * rad) (states: TURNING)",
        "*AssertionError: goal 9 not reached at t = 1.00 s: no NAV_STATUS for it "
        "(latest NAV_STATUS: goal 0 IDLE)",
    ])
    (line,) = [ln for ln in result.stdout.lines if ln.startswith("E   ") and "(exact," in ln]
    assert "heading" not in line  # within its 1.0 rad bound: not named


READING = """
import math
import pytest

def test_frames_are_decoded_with_timestamps(odocan_rig):
    rig = odocan_rig(seed=4)
    rig.drive("spin", seconds=1.0)
    poses = rig.frames("ODOM_POSE_X")
    assert 45 <= len(poses) <= 51 and poses[-1]["timestamp_s"] == pytest.approx(0.981)
    summary = rig.frames("ODOM_STATUS", PAGE="SUMMARY")
    assert {f["INTEGRATOR"] for f in summary} == {"EXACT"} and len(summary) == 10
    assert rig.latest("ODOM_STATUS", PAGE="FRAME_TOTALS")["REJECTED_FRAMES"] == 0
    assert rig.pose.heading_rad > 1.0 and rig.truth.heading_rad > 1.0
    ref = rig.reference
    assert abs(ref.heading_rad - rig.pose.heading_rad) <= 2 * math.pi / 65536
    assert rig.report()["samples"]["onboard"] == len(poses)

def test_a_path_of_goals(odocan_rig):
    rig = odocan_rig(robot="kobuki")
    ids = rig.path([(0.5, 0.0), (0.5, 0.5, math.pi)], mode="go_to_goal")
    assert ids == [1, 2]
    rig.run_until_reached(timeout_s=30)
    rig.assert_reached(1)
    states = {(f["GOAL_ID"], f["STATE"]) for f in rig.frames("NAV_STATUS")}
    assert {(1, "REACHED"), (2, "REACHED")} <= states
    rig.assert_pose_matches_reference()
"""


def test_reading_frames_pose_and_paths(pytester: pytest.Pytester) -> None:
    pytester.makepyfile(test_reading=READING)
    run(pytester).assert_outcomes(passed=2)


TEARDOWN = """
import can

RIGS = []

def test_makes_rigs_and_fails(odocan_rig):
    RIGS.extend([odocan_rig(), odocan_rig(faults="drop=0.1")])
    RIGS[0].step(0.1)
    assert not any(r.closed for r in RIGS)
    assert False, "on purpose"

def test_every_bus_was_shut_down():
    assert len(RIGS) == 2 and all(r.closed for r in RIGS)
    for rig in RIGS:
        for bus in rig.buses:
            try:
                bus.send(can.Message(arbitration_id=1, is_extended_id=False))
            except can.CanOperationError:
                continue
            raise AssertionError(f"{bus} still open")
"""


def test_teardown_closes_every_rig_even_when_the_test_fails(pytester: pytest.Pytester) -> None:
    pytester.makepyfile(test_teardown=TEARDOWN)
    result = run(pytester)
    result.assert_outcomes(failed=1, passed=1)
    result.stdout.fnmatch_lines(["*AssertionError: on purpose*"])


OPTIONS = """
import pytest

def test_ini_defaults(odocan_rig):
    rig = odocan_rig()
    rig.step(0.2)
    assert (rig.robot.name, rig.integrator) == ("kobuki", "rk2")
    assert rig.odom_status["INTEGRATOR"] == "RK2"

@pytest.mark.odocan(integrator="euler", errors="eb=1.01")
def test_marker_overrides_ini(odocan_rig):
    rig = odocan_rig()
    rig.step(0.2)
    assert rig.odom_status["INTEGRATOR"] == "EULER" and rig.options.errors == "eb=1.01"

@pytest.mark.odocan(integrator="euler")
def test_keywords_override_the_marker(odocan_rig):
    rig = odocan_rig(integrator="exact", robot="pmir")
    rig.step(0.2)
    assert rig.odom_status["INTEGRATOR"] == "EXACT" and rig.robot.name == "pmir"

@pytest.mark.odocan(integrater="euler")
def test_misspelt_marker(odocan_rig):
    pass
"""


def test_ini_options_marker_and_keywords(pytester: pytest.Pytester) -> None:
    pytester.makeini("[pytest]\nodocan_robot = kobuki\nodocan_integrator = rk2\n")
    pytester.makepyfile(test_options=OPTIONS)
    result = run(pytester)
    result.assert_outcomes(passed=3, errors=1)
    result.stdout.fnmatch_lines(["*odocan takes keywords robot, integrator*; got integrater*"])


def test_a_malformed_bus_option_is_an_error(pytester: pytest.Pytester) -> None:
    pytester.makepyfile(test_any="def test_rig(odocan_rig):\n    odocan_rig()\n")
    result = run(pytester, "--odocan-bus", "udp_multicast")
    result.assert_outcomes(errors=1)
    result.stdout.fnmatch_lines(["*odocan bus: expected KEY=VALUE, got 'udp_multicast'*"])


def test_parse_bus_spec_types_the_values() -> None:
    assert parse_bus_spec("interface=udp_multicast, channel=239.1.2.3,hop_limit=0,fd=false") == {
        "interface": "udp_multicast", "channel": "239.1.2.3", "hop_limit": 0, "fd": False,
    }
    with pytest.raises(BusSetupError, match="empty"):
        parse_bus_spec(" , ")


# --- an external firmware on udp_multicast ------------------------------------------------------


@pytest.fixture
def udp_bus() -> str:
    """A fresh loopback-only udp_multicast channel as ``--odocan-bus`` text (skip if none)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    group = f"239.255.{secrets.randbelow(250) + 1}.{secrets.randbelow(250) + 1}"
    spec = f"interface=udp_multicast,channel={group},port={port},hop_limit=0"
    kwargs: dict[str, Any] = parse_bus_spec(spec)
    try:
        rx, tx = can.Bus(**kwargs), can.Bus(**kwargs)
    except (can.CanError, OSError, ImportError) as exc:
        pytest.skip(f"udp_multicast cannot be opened here: {exc}")
    try:
        tx.send(can.Message(arbitration_id=0x7FF, data=bytes(8), is_extended_id=False))
        if rx.recv(2.0) is None:
            pytest.skip("udp_multicast does not loop back on this machine")
    finally:
        rx.shutdown()
        tx.shutdown()
    return spec


def _start_firmware(spec: str) -> subprocess.Popen[str]:
    """``odocan firmware`` (default integrator exact) on the channel of ``spec``."""
    kwargs = parse_bus_spec(spec)
    argv = [sys.executable, "-m", "odocan", "firmware", "-i", "udp_multicast",
            "-c", kwargs["channel"], "--bus-arg", f"port={kwargs['port']}",
            "--bus-arg", "hop_limit=0"]
    return subprocess.Popen(argv, cwd=ROOT, stderr=subprocess.PIPE, text=True)


def _stop(proc: subprocess.Popen[str]) -> str:
    proc.send_signal(signal.SIGTERM)
    try:
        return proc.communicate(timeout=10)[1]
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.communicate()[1]


# an external firmware's ODOM_ACK is awaited on the wall clock: a loaded CI machine (the firmware
# process starved 3 s, "set_pose ... no ODOM_ACK from the firmware") needs more than the default
ACK_TIMEOUT = ("-o", "odocan_ack_timeout=60")
ACK_CHECK = """
def test_ack_timeout(odocan_rig):
    rig = odocan_rig()
    assert rig.backend.ack_timeout_s == (60 if rig.backend.mode == "external" else 1.0)
"""


def test_the_same_file_in_lockstep_and_against_an_external_firmware(
    pytester: pytest.Pytester, udp_bus: str
) -> None:
    pytester.makepyfile(test_users_robot=EXAMPLE.read_text(), test_ack=ACK_CHECK)
    run(pytester, *ACK_TIMEOUT).assert_outcomes(passed=3)
    firmware = _start_firmware(udp_bus)
    try:
        result = run(pytester, "--odocan-bus", udp_bus, *ACK_TIMEOUT)
    finally:
        err = _stop(firmware)
    result.assert_outcomes(passed=3)
    result.stdout.fnmatch_lines([f"odocan: external firmware on {udp_bus} (real time)"])
    assert err.startswith("odocan firmware: ")
    assert "Traceback" not in err


def test_no_external_firmware_on_the_bus_is_a_clear_error(
    pytester: pytest.Pytester, udp_bus: str
) -> None:
    pytester.makepyfile(test_any="def test_rig(odocan_rig):\n    odocan_rig()\n")
    pytester.makeini("[pytest]\nodocan_attach_timeout = 1\n")
    result = run(pytester, "--odocan-bus", udp_bus)
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines(
        ["*TestkitError: no ODOM_STATUS from the firmware within 1 s: is it running on this bus?"]
    )
