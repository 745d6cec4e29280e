"""An "expired" answer on ``cmd/result`` says which rule applied (#13): the broker's MQTT v5
message expiry, the age since it arrived here, or its ``sent_unix_s``. Before, every one said
"older than its expiry: not run", and its sender could not tell which clock to fix."""

from __future__ import annotations

import json
import time
from typing import Any

import can
import pytest

from odocan.host.mqtt.client import Arrived
from odocan.host.mqtt.link import RobotLink
from tests.test_mqtt_robustness import URL, _bridge

POSE = {"id": "e", "x_m": 1.0, "y_m": 2.0, "heading_rad": 0.0}


def _arrived(age_s: float, expiry_s: float | None, **extra: Any) -> Arrived:
    payload = json.dumps({**POSE, **extra}).encode()
    message = Arrived("odocan/robot001/cmd/set_pose", payload, 1, False, 1, None)
    message.arrival_s = time.monotonic() - age_s
    message.expiry_s = expiry_s
    return message


@pytest.mark.parametrize(("message", "says"), [
    (lambda: _arrived(2.0, 1.0), "MQTT v5 message expiry"),
    (lambda: _arrived(6.0, None), "arrival age"),
    (lambda: _arrived(0.0, None, sent_unix_s=time.time() - 7.0), "sent_unix_s"),
])
def test_an_expired_answer_names_the_rule_that_applied(message: Any, says: str) -> None:
    with can.Bus(interface="virtual", channel=f"expiry-{time.monotonic_ns()}") as bus:
        robot_ = _bridge(bus).robots[0]
        link = RobotLink(robot="robot001", broker=URL, command_expiry_s=5.0,
                         on_command=robot_.on_command)
        (_, answer), = link._answer("set_pose", message())
        assert robot_.commands_sent == 0
    assert (answer["id"], answer["result"]) == ("e", "expired")
    assert says in answer["reason"], answer["reason"]
    others = {"MQTT v5 message expiry", "arrival age", "sent_unix_s"} - {says}
    assert not any(other in answer["reason"] for other in others), answer["reason"]
    assert link.commands_expired == 1
