"""``odocan fleet --secoc-key``: robots that verify their commands, bridges that sign them.

Each robot's firmware holds its own key, derived from the fleet key (``sim.provision``, NIST
SP 800-108 counter mode with AES-CMAC); the derivation is checked against ``cryptography``'s CMAC.
A fleet runs in real time on the embedded broker and takes commands through MQTT: the robot whose
bridge signs them acks, the robot whose bridge has no key answers NACK AUTH_MISSING on
``cmd/result``.
"""

from __future__ import annotations

import asyncio
import json
from contextlib import suppress
from pathlib import Path
from typing import Any

import pytest
from cryptography.hazmat.primitives.ciphers import algorithms
from cryptography.hazmat.primitives.cmac import CMAC

from odocan.host.mqtt import topics
from odocan.host.mqtt.broker import EmbeddedBroker
from odocan.host.mqtt.fleetrun import FleetRun, run_fleet
from odocan.sim import robot
from odocan.sim.fleet import FleetConfig
from odocan.sim.provision import robot_key
from tests.conftest_mqtt import client
from tests.fleet_run_until import pace_never_late
from tests.test_secoc import KEY
from tests.test_secoc_host import one_line_error

SIGNED, UNSIGNED = "robot001", "robot002"


def reference_robot_key(fleet_key: bytes, name: str) -> bytes:
    """SP 800-108r1 4.1, written out from the standard with ``cryptography``'s AES-CMAC."""
    fixed = b"\x01" + b"odocan-secoc" + b"\x00" + name.encode() + (128).to_bytes(2, "big")
    mac = CMAC(algorithms.AES(fleet_key))
    mac.update(fixed)
    return mac.finalize()


def test_each_robot_key_is_the_sp800_108_derivation_of_the_fleet_key() -> None:
    names = [f"robot{i:03d}" for i in range(1, 41)]
    keys = [robot_key(KEY, name) for name in names]
    assert keys == [reference_robot_key(KEY, name) for name in names]
    assert len(set(keys)) == len(names)  # one key per robot, none the fleet key
    assert KEY not in keys
    with pytest.raises(ValueError, match="15"):
        robot_key(KEY[:15], "robot001")


async def fleet_answers(commands: list[tuple[str, str, dict[str, Any]]]) -> list[dict[str, Any]]:
    """Run a 2-robot SecOC fleet (robot002's bridge without a key), publish ``commands``
    (robot, command, payload) once both robots' poses are on the broker (so each bridge has
    seen its firmware's boot ODOM_FRESHNESS), and return every cmd/result answer. The fleet's
    duration is ample (a loaded machine starts it slowly); it is cancelled once all are in."""
    async with EmbeddedBroker() as broker, client(broker.url) as operator:
        await operator.subscribe(f"odocan/+/{topics.RESULT_LEAF}", qos=1)
        await operator.subscribe("odocan/+/pose", qos=0)
        run = FleetRun(
            fleet=FleetConfig(robots=2, robot=robot.load("pmir"), seed=5, secoc_key=KEY),
            duration_s=60.0, broker=broker.url, client_prefix="test-fleet-secoc",
            secoc_unsigned=frozenset({UNSIGNED}),
        )
        task = asyncio.create_task(run_fleet(run))
        answers: list[dict[str, Any]] = []
        posed: set[str] = set()
        async with asyncio.timeout(60):
            async for message in operator.messages:
                assert isinstance(message.payload, bytes)
                robot_name, leaf = message.topic.value.split("/", 2)[1:]
                if leaf == "pose":
                    if len(posed) < 2:
                        posed.add(robot_name)
                        if len(posed) == 2:
                            await _publish(operator, commands)
                    continue
                answers.append({"robot": robot_name, **json.loads(message.payload)})
                if sum(a["result"] in ("acked", "nacked") for a in answers) == len(commands):
                    break
        task.cancel()
        with suppress(asyncio.CancelledError):
            await task
    return answers


async def _publish(operator: Any, commands: list[tuple[str, str, dict[str, Any]]]) -> None:
    for name, command, payload in commands:
        await operator.publish(topics.topic(name, f"cmd/{command}"), json.dumps(payload), qos=1)


def test_a_fleet_command_is_acked_with_the_key_and_nacked_auth_without_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    pace_never_late(monkeypatch)  # a halted MCU (a loaded machine) loses what it was sent
    pose = {"x_m": 1.5, "y_m": -2.0, "heading_rad": 0.5}
    answers = asyncio.run(fleet_answers([
        (SIGNED, "set_pose", {"id": "signed-pose", **pose}),
        (SIGNED, "nav_goal", {"id": "signed-goal", "x_m": 2.0, "y_m": -2.0, "goal_id": 7}),
        (UNSIGNED, "set_pose", {"id": "unsigned-pose", **pose}),
    ]))
    final = {a["id"]: a for a in answers if a["result"] in ("acked", "nacked")}
    sent = {a["id"]: a for a in answers if a["result"] == "accepted"}
    assert set(sent) == {"signed-pose", "signed-goal", "unsigned-pose"}  # all reached the bus
    assert final["signed-pose"]["result"] == "acked", final
    assert final["signed-pose"]["robot"] == SIGNED
    assert final["signed-goal"]["result"] == "acked", final
    assert final["unsigned-pose"] == {**final["unsigned-pose"], "robot": UNSIGNED,
                                      "result": "nacked", "reason": "AUTH_MISSING"}


def test_a_bad_fleet_key_file_is_one_line_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    short = tmp_path / "short.key"
    short.write_bytes(KEY[:15])
    short.chmod(0o600)
    err = one_line_error(capsys, "fleet", "--secoc-key", str(short), "--duration", "1")
    assert str(short) in err
    assert "15 bytes" in err
    missing = tmp_path / "absent.key"
    err = one_line_error(capsys, "fleet", "--secoc-key", str(missing), "--duration", "1")
    assert str(missing) in err
    unreadable = tmp_path / "a-directory.key"  # unreadable even for root
    unreadable.mkdir()
    err = one_line_error(capsys, "fleet", "--secoc-key", str(unreadable), "--duration", "1")
    assert str(unreadable) in err
