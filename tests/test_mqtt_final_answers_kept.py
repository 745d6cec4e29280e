"""A full QoS-1 buffer drops a command's interim answer (``accepted``) before any final one.

Measured with 1 500 ``set_pose`` at once (mosquitto, operator in another process): the bridge's
QoS-1 buffer (1 000) overflowed by 163-177 publications, the oldest first, whatever they were:
1 299-1 359 of the 1 500 commands got their final answer, the rest none. A command's
``accepted`` only says it was taken; its final answer (acked, nacked, expired, rejected,
timeout, aborted) is the one its sender waits for. Statuses (superseded by the next) go first,
then interim answers, then the oldest.
"""

from __future__ import annotations

import json

from odocan.host.mqtt import topics
from odocan.host.mqtt.broker import BrokerURL
from odocan.host.mqtt.link import RobotLink


def test_a_full_qos1_buffer_drops_interim_answers_before_final_ones() -> None:
    link = RobotLink(robot="robot001", broker=BrokerURL("127.0.0.1", 1883),
                     on_command=lambda n, p, v: [], reliable_buffer=10)
    link.connected.set()
    link.publish(topics.RESULT_LEAF, {"id": 0, "result": "accepted"})
    link.publish(topics.RESULT_LEAF, {"id": 0, "result": "timeout"})
    for k in range(1, 12):  # a flood's answers: the buffer overflows
        link.publish(topics.RESULT_LEAF, {"id": k, "result": "accepted"})
    kept = [json.loads(p.body) for p in link.reliable]
    assert len(kept) == 10
    assert {"id": 0, "result": "timeout"} in kept  # the final answer stays
    assert [r["id"] for r in kept if r["result"] == "accepted"] == list(range(3, 12))
