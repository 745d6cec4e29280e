"""Whether a broker speaks MQTT v5 (``host.mqtt.link.RobotLink`` asks once per broker): amqtt
answers a plain v5 CONNECT with "unsupported protocol version", and is then spoken to in 3.1.1."""

from __future__ import annotations

import asyncio
import logging
import weakref

import aiomqtt

from odocan.host.mqtt.broker import (
    BrokerError,
    BrokerURL,
    first_connect_failure,
    protocol_unsupported,
)

log = logging.getLogger("odocan.mqtt")
CLIENT_LOG = logging.getLogger("odocan.mqtt.client")  # aiomqtt, paho: quiet unless --debug

_V5_SEEN: weakref.WeakKeyDictionary[
    asyncio.AbstractEventLoop, tuple[asyncio.Lock, dict[tuple[str, int], bool]]
] = weakref.WeakKeyDictionary()  # per event loop: its lock and the answers


async def speaks_v5(broker: BrokerURL, timeout_s: float) -> bool:
    """Whether ``broker`` speaks MQTT v5, from one plain v5 CONNECT (no will, no properties:
    amqtt misreads a v5 CONNECT with properties and never answers). Cached per host and port
    for the running event loop;
    ``BrokerError`` when the broker cannot be used at all (refused, not authorized, TLS, DNS)."""
    loop = asyncio.get_running_loop()
    lock, seen = _V5_SEEN.setdefault(loop, (asyncio.Lock(), {}))
    async with lock:
        key = (broker.host, broker.port)
        if key not in seen:
            seen[key] = await _probe_v5(broker, timeout_s)
        return seen[key]


async def _probe_v5(broker: BrokerURL, timeout_s: float) -> bool:
    client = aiomqtt.Client(**broker.client_kwargs(), protocol=aiomqtt.ProtocolVersion.V5,
                            timeout=timeout_s, logger=CLIENT_LOG)
    client._client.connect_timeout = timeout_s
    try:
        async with asyncio.timeout(timeout_s + 1.0), client:
            return True
    except (aiomqtt.MqttError, TimeoutError, OSError) as exc:
        if protocol_unsupported(exc):
            log.info("%s speaks MQTT 3.1.1 only: no reason codes, no message expiry", broker)
            return False
        reason = await first_connect_failure(exc, broker, timeout_s)
        raise BrokerError(f"cannot connect to {broker}: {reason}") from None
