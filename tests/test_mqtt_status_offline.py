"""After a broker outage the bridge no longer replays every ``status`` queued meanwhile (#13):
``status`` is retained, so the broker keeps only the latest anyway; 14 of them went out in a burst
of 5 s. Queued while disconnected, a new one replaces the queued ones (counted); results stay."""

from __future__ import annotations

import json

from odocan.host.mqtt import topics
from tests.test_mqtt_robustness import _link


def test_offline_only_the_latest_status_stays_queued_and_the_rest_are_counted() -> None:
    link = _link()
    for k in range(14):
        link.publish(topics.STATUS_LEAF, {"seq": k})
        if k % 7 == 0:
            link.publish(topics.RESULT_LEAF, {"id": k})
    kept = [json.loads(p.body) for p in link.reliable]
    assert kept == [{"id": 0}, {"id": 7}, {"seq": 13}]  # every result, the newest status
    assert link.counters()["status_superseded"] == 13
    assert link.reliable_dropped == 0


def test_connected_every_status_is_sent_in_order() -> None:
    link = _link()
    link.connected.set()
    for k in range(3):
        link.publish(topics.STATUS_LEAF, {"seq": k})
    assert [json.loads(p.body)["seq"] for p in link.reliable] == [0, 1, 2]
    assert link.counters()["status_superseded"] == 0
