"""A bridge stopped with its command queue full answers every command it read (#13 part 4).

Commands the command reader read (paho acknowledged them: the broker will not send them again)
and the link had not taken yet are answered when the bridge stops (``aborted``, or ``expired``).
They went into the link's QoS-1 buffer like any publication, and the buffer drops its oldest
entry beyond ``reliable_buffer``: with up to ``COMMAND_QUEUE`` (1 000) commands waiting, most of
their answers were pushed out unsent, unanswered and unreported. Here a real mosquitto, the
bridge's loop blocked until ``COMMAND_QUEUE`` commands wait in the reader's queue (an operator
on paho's own thread floods them), then stopped at once: every command the broker acknowledged
must get its final answer, and none may be dropped from the buffer.
"""

from __future__ import annotations

import asyncio
import time

from odocan.host.mqtt.cmdreader import COMMAND_QUEUE
from tests.conftest_mqtt import Mosquitto, mosquitto  # noqa: F401 (fixture)
from tests.test_bridge_cmd_stall import _Operator
from tests.test_mqtt_bridge import ROBOT, running_bridge

RELIABLE = 200  # the QoS-1 buffer: fewer than the answers owed at the stop
WAIT_S = 60.0  # a safety net against a hang, never a timing assertion


def test_commands_waiting_in_a_full_queue_at_the_stop_are_all_answered(
    mosquitto: Mosquitto,  # noqa: F811
) -> None:
    operator = _Operator(mosquitto.url(ROBOT))

    async def scenario() -> tuple[int, dict[str, int]]:
        async with running_bridge(mosquitto.url("bridge"), reliable_buffer=RELIABLE,
                                  command_expiry_s=600.0) as (bridge, _):
            operator.start()
            assert await asyncio.to_thread(operator.subscribed.wait, 10)
            operator.flood(COMMAND_QUEUE)
            waiting = bridge.commands.robots[ROBOT].arrived
            deadline = time.monotonic() + WAIT_S
            while len(waiting) < COMMAND_QUEUE and time.monotonic() < deadline:
                time.sleep(0.01)  # the loop blocked: the link takes none
            queued = len(waiting)
        deadline = time.monotonic() + WAIT_S  # the bridge has stopped: its answers come
        while operator.unanswered() and time.monotonic() < deadline:
            await asyncio.sleep(0.2)
        return queued, dict(bridge.counters())

    try:
        queued, counters = asyncio.run(scenario())
    finally:
        operator.stop()
    assert queued == COMMAND_QUEUE  # the stop found the queue full
    assert len(operator.acknowledged) == COMMAND_QUEUE
    missing = operator.unanswered()
    assert not missing, f"{len(missing)} of {COMMAND_QUEUE} acknowledged commands never answered"
    assert (counters["reliable_dropped"], counters["answers_unsent"]) == (0, 0), counters
