"""Without ``--robot``, the live judges (``odocan monitor``, ``odocan bridge``) do not judge a
firmware whose PROFILE page is not the default robot's (``host.judge.liverobot``, issue #11).

Before, they judged a custom robot's correct firmware as the default pmir and FAILed it ("the
on-board pose was wrong ...; judged as robot 'pmir' (the default robot)") for an option the
user did not give; ``analyze`` of the same log refuses it (exit 2). Now the watch says why it
judges nothing ("the firmware runs a different profile than the default robot pmir: give
--robot") and ends UNJUDGED (``--require-firmware``: FAIL), and a robot given is still judged:
a pose tampered by 1 m under ``--robot`` the firmware's own profile FAILs. The custom profile
(``ODD``: 32-bit counters, another wheelbase and wheels) fits no shipped robot by the test's
own CRC-32 of the DBC comment's parameter bytes (``tests.test_profile_page``).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import can
import pytest

from odocan.firmware import frames as fr
from odocan.host.cli.app import main
from odocan.host.judge.liverobot import PAGE_PERIOD_S, PAGE_WAIT_S
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.reference import Geometry
from odocan.host.judge.watchend import end_watch
from odocan.host.judge.watchverdict import failures
from odocan.host.mqtt.endverdict import end_verdict
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.host.protocol.busfacts import PROFILE_PAGE
from odocan.sim import robot
from odocan.sim.contract import database
from tests import host_frames as hf
from tests.test_cli_monitor import BOUND, Source, sources
from tests.test_cli_run import run_cli
from tests.test_profile_page import crc32_iso_hdlc, parameter_bytes
from tests.test_robot_from_log import ODD

WHY = "the firmware runs a different profile than the default robot pmir: give --robot"
UNJUDGED = {"name": "pmir", "source": "default", "page_fits": [], "unjudged": WHY}
DB = database()
STATUS = DB.get_message_by_name("ODOM_STATUS")
POSE_X = DB.get_message_by_name("ODOM_POSE_X")
TAMPER_FROM_S = 1.5  # the pose moved 1 m from here on
LATE_S = 2.0  # no PROFILE page before (``late``): after the wait for it (PAGE_WAIT_S)


@pytest.fixture(scope="module")
def odd(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A 3 s lockstep drive of the custom profile ``ODD``, its TOML beside it."""
    folder = tmp_path_factory.mktemp("odd_robot")
    toml = folder / "odd.toml"
    toml.write_text(ODD)
    log = folder / "odd.log"
    assert main(["run", "--robot", str(toml), "--duration", "3", "--seed", "2", "--log",
                 str(log)]) == 0
    return {"toml": toml, "log": log}


def frames(log: Path) -> list[can.Message]:
    return list(can.LogReader(str(log)))


def page(msg: can.Message) -> dict[str, Any] | None:
    """The ODOM_STATUS page ``msg`` carries (raw), None for another message."""
    if msg.arbitration_id != STATUS.frame_id:
        return None
    signals: Any = STATUS.decode(bytes(msg.data), decode_choices=False)
    return dict(signals)


def tampered(messages: list[can.Message]) -> list[can.Message]:
    """Every ODOM_POSE_X from ``TAMPER_FROM_S`` on 1 m further in X, its CRC made anew."""
    one_m = round(1.0 / POSE_X.get_signal_by_name("X").scale)
    out = []
    for msg in messages:
        if msg.arbitration_id == POSE_X.frame_id and msg.timestamp >= TAMPER_FROM_S:
            raw: Any = POSE_X.decode(bytes(msg.data), decode_choices=False, scaling=False)
            raw["X"] += one_m
            data = bytearray(POSE_X.encode(raw, scaling=False))
            hf.p02_protect(data, int(raw["COUNTER"]), fr.ODOM_POSE_X_DATA_IDS)
            msg = can.Message(arbitration_id=msg.arbitration_id, data=bytes(data),
                              is_extended_id=False, timestamp=msg.timestamp)
        out.append(msg)
    return out


def late(messages: list[can.Message], until_s: float = LATE_S) -> list[can.Message]:
    """The drive without its PROFILE pages before ``until_s``: the first comes after the wait
    for it (``liverobot.PAGE_WAIT_S``) ended."""
    assert until_s > PAGE_WAIT_S + messages[0].timestamp
    return [m for m in messages
            if m.timestamp >= until_s or (page(m) or {}).get("PAGE") != PROFILE_PAGE]


def watched(messages: list[can.Message], given: robot.RobotProfile | None
            ) -> tuple[BusMonitor, list[str]]:
    """``messages`` fed to the monitor's model (``given``: ``--robot``; None: not given)."""
    model = BusMonitor(given or robot.load("pmir"), from_page=given is None)
    for msg in messages:
        model.feed(msg, now_s=msg.timestamp)
    model.release_held()
    end_watch(model.tracker, model.distance)
    return model, failures(model.tracker, model.distance, model.twist, model.sources, "")


def bridged(messages: list[can.Message], given: robot.RobotProfile | None
            ) -> tuple[RobotTelemetry, list[tuple[str, dict[str, Any]]]]:
    """``messages`` fed to the bridge's telemetry; it and every publication it made."""
    profile = given or robot.load("pmir")
    telemetry = RobotTelemetry("r", Geometry.of(profile), "exact",
                               counter_bits=profile.counter_bits, profile_name=profile.name,
                               from_page=given is None)
    published = [p for msg in messages for p in telemetry.feed(msg)]
    published += telemetry.end_watch()
    return telemetry, published


def test_the_drives_page_fits_no_shipped_robot_by_the_tests_own_crc(
        odd: dict[str, Path]) -> None:
    """The premise: the page is ODD's, and no shipped robot's with any integrator."""
    crcs = {int(s["PROFILE_CRC"]) for m in frames(odd["log"])
            if (s := page(m)) is not None and s["PAGE"] == PROFILE_PAGE}
    assert crcs == {crc32_iso_hdlc(parameter_bytes(robot.load(str(odd["toml"])), "exact"))}
    shipped = {crc32_iso_hdlc(parameter_bytes(robot.load(name), integrator))
               for name in robot.list_profiles() for integrator in ("euler", "rk2", "exact")}
    assert not crcs & shipped


@pytest.mark.parametrize("arrives", ["in the wait", "after the wait"])
def test_the_monitor_does_not_judge_a_custom_robot_as_pmir(
        odd: dict[str, Path], arrives: str) -> None:
    messages = frames(odd["log"])
    model, fails = watched(messages if arrives == "in the wait" else late(messages), None)
    assert fails == [], "a correct firmware blamed for a --robot not given"
    assert model.robot.as_dict() == UNJUDGED
    assert model.tracker.vs_reference.samples == 0  # nothing judged with pmir
    assert model.tracker.pose is not None  # the on-board pose still followed and shown
    health = model.snapshot(messages[-1].timestamp)["health"]
    assert (health["state"], health["why"]) == ("UNVERIFIED", [WHY])
    assert health["pose_wrongs"]["episodes"] == 0


@pytest.mark.parametrize("arrives", ["in the wait", "after the wait"])
def test_the_bridge_does_not_judge_a_custom_robot_as_pmir(
        odd: dict[str, Path], arrives: str) -> None:
    messages = frames(odd["log"])
    telemetry, published = bridged(messages if arrives == "in the wait" else late(messages),
                                   None)
    verdict = end_verdict(telemetry, profile_name="pmir")
    assert verdict.verdict == "UNJUDGED", verdict.text
    assert verdict.reason.startswith(f"{WHY} (--require-firmware fails it)"), verdict.reason
    assert verdict.pose_error is None
    required = end_verdict(telemetry, profile_name="pmir", require_firmware=True)
    assert required.verdict == "FAIL"
    assert required.reason.startswith(f"{WHY} (--require-firmware)"), required.reason
    status = telemetry.status()[1]
    assert status["robot_profile"] == UNJUDGED
    assert status["pose_wrongs"]["episodes"] == 0
    since_s = 0.0 if arrives == "in the wait" else LATE_S + PAGE_PERIOD_S  # the page came
    assert not [body for leaf, body in published  # no error vs pmir (once the page came)
                if leaf == "error" and body["t_s"] >= since_s]
    poses = [body for leaf, body in published if leaf == "pose"]  # the pose still bridged
    assert poses
    assert poses[-1]["t_s"] > messages[-1].timestamp - 0.2, poses[-1]


def test_a_tampered_pose_under_the_robot_given_still_fails(odd: dict[str, Path]) -> None:
    """``--robot`` the firmware's own profile: the drive passes, and 1 m added to the pose
    FAILs in the monitor and the bridge (nothing of the above spares a robot given)."""
    given = robot.load(str(odd["toml"]))
    clean, bad = frames(odd["log"]), tampered(frames(odd["log"]))
    assert watched(clean, given)[1] == []
    model, fails = watched(bad, given)
    assert model.robot.as_dict()["source"] == "--robot"
    assert fails
    assert fails[0].startswith("the on-board pose was wrong"), fails
    assert end_verdict(bridged(clean, given)[0], profile_name="odd").verdict == "PASS"
    verdict = end_verdict(bridged(bad, given)[0], profile_name="odd")
    assert verdict.verdict == "FAIL", verdict.text
    assert verdict.reason.startswith("the on-board pose was wrong"), verdict.reason
    assert verdict.pose_error is not None
    assert verdict.pose_error["dpos_mm"] > 900


def test_a_tampered_pose_without_robot_is_never_a_pass(odd: dict[str, Path]) -> None:
    """Unjudged is no PASS: the tampered drive without ``--robot`` ends UNJUDGED."""
    telemetry, _ = bridged(tampered(frames(odd["log"])), None)
    assert end_verdict(telemetry, profile_name="pmir").verdict == "UNJUDGED"


@pytest.fixture
def odd_rig(monkeypatch: pytest.MonkeyPatch, odd: dict[str, Path]) -> Iterator[Source]:
    """A live rig of the custom robot (3 s: five PROFILE pages) for ``odocan monitor``."""
    yield from sources(monkeypatch, robot_name=str(odd["toml"]), ticks=300, garbage=False)


def test_odocan_monitor_without_robot_ends_unjudged_on_a_custom_robot(
    odd_rig: Source, capsys: pytest.CaptureFixture[str]
) -> None:
    """The trial's command on a live custom rig: no pose FAIL; ``--require-firmware`` FAILs
    it for want of --robot, the JSON says why (its state at the end: STALE, the rig gone)."""
    code, out, err = run_cli(capsys, "monitor", "-i", "virtual", "-c", odd_rig.channel,
                             "--duration", BOUND, "--json", "--require-firmware")
    assert code == 1, err
    lines = err.splitlines()
    assert f"monitor: FAIL: {WHY} (--require-firmware)" in lines, err
    assert not [line for line in lines if "pose was wrong" in line], err
    snapshot = json.loads(out)
    assert snapshot["robot"] == UNJUDGED
    assert snapshot["health"]["pose_wrongs"]["episodes"] == 0


def test_odocan_bridge_without_robot_ends_unjudged_on_a_custom_robot(
    odd: dict[str, Path], monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """``odocan bridge`` (an embedded broker) hearing the custom drive: UNJUDGED, exit 0."""
    from tests.test_bridge_exit import _bridge_hears, _duration_reached
    from tests.test_stall_bound import _messages

    _bridge_hears(monkeypatch, _messages(odd["log"]), _duration_reached)
    code, _, err = run_cli(capsys, "bridge", "-i", "virtual", "--duration", "600")
    assert code == 0, err
    assert err.splitlines()[-1].startswith(
        f"bridge robot001: UNJUDGED: {WHY} (--require-firmware fails it)"), err
