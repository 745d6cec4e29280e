"""Every command the broker acknowledged is answered, while the bridge's loop is blocked (#13.4).

Found by the last pass (``host.mqtt.stallwatch``): with the bridge's event loop blocked 6 s under
a 1 500-command flood, mosquitto 2.0 (20 in flight + 1 000 queued per client by default) logged
"Outgoing messages are being dropped" and dropped commands it had already acknowledged to their
sender: about 480 of 1 500 were never answered on ``cmd/result``. Here: a real mosquitto with
its default limits, the bridge's loop blocked ``BLOCK_S`` (``time.sleep`` in the loop's thread:
a fleet's tick, a GC pause), and an operator in its own thread (paho's network thread: it goes
on publishing and listening while the loop is blocked) flooding ``set_pose`` at QoS 1. Every
command the broker acknowledged (PUBACK) must end with a final answer on ``cmd/result``
(``rejected``, ``expired``, ``timeout``…; no firmware is on the bus), and none may run after its
expiry: a command that waited longer than ``--command-expiry`` is ``expired``, never
``accepted``. When the bridge has stopped, no thread of its command reader is left.

The operator reads ``cmd/result`` at QoS 0 (CI, stop 50: 35 of 1 500 never answered, the busy
answers 1252 on, with ``reliable_dropped`` 0): mosquitto bounds the QoS-1 messages it holds for
a subscriber (20 in flight + 1 000), and this operator shares the bridge's process and GIL, so
on a loaded machine the 1 000 ``expired`` answers the loop sends at once when it resumes, with
busy answers still coming from the reader, overflowed its queue and the broker dropped answers
the bridge had published. Measured (mosquitto 2.0.11, 3 000 QoS-1 publications at once, a
subscriber taking 2 ms a message): 1 047 (v5) and 1 140 (3.1.1) of 3 000 reach it at QoS 1,
all 3 000 at QoS 0 (a connected client's QoS-0 messages are not counted). What is judged here
is the bridge, not the broker's bound on a slow operator (docs/mqtt.md says it for operators).
"""

from __future__ import annotations

import asyncio
import json
import os
import threading
import time
from typing import Any

import paho.mqtt.client as paho
import pytest
from paho.mqtt.enums import CallbackAPIVersion

from odocan.host.mqtt import client, cmdreader, topics
from odocan.host.mqtt.broker import BrokerURL
from odocan.host.mqtt.expiry import Fresh
from tests.bridge_pair import bridged_robot
from tests.conftest_mqtt import Mosquitto, mosquitto  # noqa: F401 (fixture)
from tests.test_mqtt_bridge import ROBOT, running_bridge

FLOOD = 1500  # mosquitto holds 20 in flight + 1 000 queued for a client that does not read
BLOCK_S = 6.0
EXPIRY_S = 3.0  # the bridge's --command-expiry: shorter than the block
FINAL = {"acked", "nacked", "expired", "rejected", "timeout", "aborted"}


class _Operator:
    """Robot001's operator on paho's own network thread: publishes, counts PUBACKs, listens."""

    def __init__(self, url: BrokerURL) -> None:
        self.client = paho.Client(CallbackAPIVersion.VERSION2,
                                  client_id=f"test-flood-{os.getpid()}", protocol=paho.MQTTv5)
        self.client.username_pw_set(url.username, url.password)
        self.client.on_publish = self._on_publish
        self.client.on_message = self._on_message
        self.url = url
        self.lock = threading.Lock()
        self.subscribed = threading.Event()
        self.client.on_subscribe = lambda *_: self.subscribed.set()
        self.mids: dict[int, int] = {}  # message id -> command id
        self.acked_mids: set[int] = set()  # message ids the broker acknowledged (PUBACK)
        self.answers: dict[int, list[str]] = {}  # command id -> its results, in order
        self.sent_unix_s: dict[int, float] = {}  # command id -> when it was published
        self.accepted_unix_s: dict[int, float] = {}  # command id -> its ``accepted``'s stamp

    def start(self) -> None:
        self.client.connect(self.url.host, self.url.port)
        self.client.subscribe(topics.topic(ROBOT, topics.RESULT_LEAF), qos=0)  # see above
        self.client.loop_start()

    def flood(self, n: int) -> None:
        for k in range(n):
            payload = json.dumps({"id": k, "x_m": 1, "y_m": 0, "heading_rad": 0}).encode()
            sent_unix_s = time.time()  # (paho calls on_publish holding a lock publish takes)
            info = self.client.publish(topics.topic(ROBOT, "cmd/set_pose"), payload, qos=1)
            with self.lock:
                self.sent_unix_s[k] = sent_unix_s
                self.mids[info.mid] = k

    @property
    def acknowledged(self) -> set[int]:
        """The command ids the broker acknowledged (PUBACK)."""
        with self.lock:
            return {self.mids[mid] for mid in self.acked_mids if mid in self.mids}

    def stop(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()

    def unanswered(self) -> set[int]:
        acknowledged = self.acknowledged
        with self.lock:
            return {k for k in acknowledged if not FINAL & set(self.answers.get(k, []))}

    def _on_publish(self, client: Any, userdata: Any, mid: int, reason: Any,
                    properties: Any) -> None:
        with self.lock:
            if not reason.is_failure:
                self.acked_mids.add(mid)

    def _on_message(self, client: Any, userdata: Any, message: paho.MQTTMessage) -> None:
        answer = json.loads(message.payload)
        with self.lock:
            self.answers.setdefault(answer["id"], []).append(answer["result"])
            if answer["result"] == "accepted":
                self.accepted_unix_s[answer["id"]] = answer["unix_s"]


def arrivals_recorded(monkeypatch: pytest.MonkeyPatch) -> dict[Any, float]:
    """Command id -> when the bridge's command reader read it first (wall clock s, as paho
    read it: ``Arrived.arrival_s``; every command comes through the reader): the
    ``--command-expiry`` of a command without ``sent_unix_s`` counts from there
    (``host.mqtt.expiry``), not from the operator's publication (the broker, starved on a
    loaded machine, may pass it on a second later)."""
    arrived_unix_s: dict[Any, float] = {}
    stamped = client.arrived_of

    def recorded(message: paho.MQTTMessage) -> client.Arrived:
        arrived = stamped(message)
        unix_s = time.time() - (time.monotonic() - arrived.arrival_s)
        arrived_unix_s.setdefault(json.loads(arrived.payload)["id"], unix_s)
        return arrived

    monkeypatch.setattr(cmdreader, "arrived_of", recorded)  # the reader's own import of it
    return arrived_unix_s


def test_every_acknowledged_command_is_answered_when_the_bridge_loop_is_blocked(
    mosquitto: Mosquitto, monkeypatch: pytest.MonkeyPatch,  # noqa: F811
) -> None:
    operator = _Operator(mosquitto.url(ROBOT))
    arrived_unix_s = arrivals_recorded(monkeypatch)

    async def scenario() -> dict[str, int]:
        async with running_bridge(mosquitto.url("bridge"), command_expiry_s=EXPIRY_S) as (
                bridge, _):
            operator.start()
            assert await asyncio.to_thread(operator.subscribed.wait, 10)
            operator.flood(FLOOD)
            time.sleep(BLOCK_S)  # the bridge's loop blocked while the flood arrives
            deadline = time.monotonic() + 40
            while operator.unanswered() and time.monotonic() < deadline:
                await asyncio.sleep(0.2)
        return dict(bridge.counters())

    try:
        counters = asyncio.run(scenario())
    finally:
        operator.stop()
    left = [t.name for t in threading.enumerate() if t.name.startswith("mqtt-cmd-")]
    assert left == []  # the bridge stopped: its command reader's thread is joined
    assert len(operator.acknowledged) == FLOOD  # the broker took them all
    assert counters["reliable_dropped"] == 0, counters  # no answer pushed out of the buffer
    missing = operator.unanswered()
    assert not missing, f"{len(missing)} of {FLOOD} acknowledged commands never answered"
    # none ran after its expiry: an ``accepted`` is stamped when the bridge ran it, its age
    # counted from its arrival (0.5 s: the stamp after the check, in the same call)
    late = {k: round(t - arrived_unix_s[k], 1) for k, t in operator.accepted_unix_s.items()
            if t - arrived_unix_s[k] > EXPIRY_S + 0.5}
    assert not late, f"{len(late)} ran after their expiry (id: age s): {list(late.items())[:5]}"


def test_a_command_that_spent_its_life_waiting_to_be_read_expires_in_the_pacers_queue() -> None:
    """A command taken from the reader's queue with 0.1 s of its life left (it waited there
    through a stall) and queued behind another in the pacer: it expires 0.1 s later, not
    ``--command-expiry`` after it reached the pacer (the pacer counted from then)."""
    with bridged_robot(f"cmd-stall-{os.getpid()}", command_window_frames=1) as (robot_, _):
        first = b'{"id": "a", "x_m": 1, "y_m": 0, "heading_rad": 0}'
        late = b'{"id": "b", "x_m": 2, "y_m": 0, "heading_rad": 0}'
        robot_.on_command("set_pose", first, Fresh(EXPIRY_S))  # takes the window: no firmware
        answers = robot_.on_command("set_pose", late, Fresh(0.1))
        assert [p["result"] for _, p in answers] == ["accepted"]  # queued behind the first
        time.sleep(0.3)
        later = robot_.paced([])
    assert [(p["id"], p["result"]) for _, p in later] == [("b", "expired")]
