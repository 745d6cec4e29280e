"""One queued QoS-1 publication of a robot's link (``host.mqtt.link.RobotLink``'s buffer) and
its send, once per connection."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from odocan.host.mqtt.client import LinkClient


@dataclass(eq=False)
class Outgoing:
    """One queued QoS-1 publication (identity matters: equal payloads are distinct entries)."""

    topic: str
    body: bytes
    retain: bool
    interim: bool = False  # a command's ``accepted``: dropped before final answers
    sent_on: object = None  # the connection (client) paho took it on, its info: not sent twice
    info: Any = None


async def publish_once(client: LinkClient, p: Outgoing) -> None:
    """``p`` to the broker and its PUBACK awaited; once per connection: an entry paho already
    took on ``client`` (its wait cancelled, the bridge stopping: ``_goodbye`` flushes the buffer
    on the same connection) is waited for, not sent again (20 ``accepted`` went out twice). On
    a new connection it is sent again (at least once: its PUBACK may never have come)."""
    if p.sent_on is not client:
        p.info, p.sent_on = client.publish_reliable(p.topic, p.body, p.retain), client
    await client.acknowledged(p.info)
