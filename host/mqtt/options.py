"""Command-line options shared by ``odocan bridge`` and ``odocan fleet``, and the broker to use."""

from __future__ import annotations

import argparse
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

from odocan.host.mqtt.broker import BrokerURL, EmbeddedBroker
from odocan.sim.exceptions import ConfigurationError


def add_mqtt_arguments(parser: argparse.ArgumentParser) -> None:
    """``--broker``, ``--ca``, ``--cert``, ``--key``, ``--publish-hz``, ``--client-prefix``."""
    group = parser.add_argument_group("MQTT (without --broker: an embedded amqtt broker)")
    group.add_argument(
        "--broker", metavar="URL",
        help="mqtt://[user:pass@]host[:port] or mqtts://... (default: start an embedded broker "
        "on a free 127.0.0.1 port)",
    )
    group.add_argument("--ca", type=Path, help="CA certificate (PEM) for mqtts://")
    group.add_argument("--cert", type=Path, help="client certificate (PEM) for mqtts://")
    group.add_argument("--key", type=Path, help="client key (PEM) for mqtts://")
    group.add_argument(
        "--publish-hz", type=float, default=10.0, metavar="HZ",
        help="pose/reference/error publications per robot and second (default: 10)",
    )
    group.add_argument(
        "--client-prefix", default="odocan-bridge",
        help="MQTT client ids are PREFIX-<robot> (persistent sessions; default: odocan-bridge)",
    )


def broker_url(args: argparse.Namespace) -> BrokerURL | None:
    """The ``--broker`` given (None: embedded); checks the TLS files exist."""
    for name in ("ca", "cert", "key"):
        path = getattr(args, name, None)
        if path is not None and not path.is_file():
            raise ConfigurationError(f"--{name} {path}: no such file")
    if args.publish_hz <= 0:
        raise ConfigurationError(f"--publish-hz must be positive, got {args.publish_hz}")
    if args.broker is None:
        if args.ca or args.cert or args.key:
            raise ConfigurationError("--ca/--cert/--key need --broker mqtts://...")
        return None
    return BrokerURL.parse(args.broker, ca=args.ca, cert=args.cert, key=args.key)


@asynccontextmanager
async def broker_for(url: BrokerURL | None) -> AsyncIterator[tuple[BrokerURL, bool]]:
    """``(url, embedded)``: ``url`` itself, or an embedded broker for the duration."""
    if url is not None:
        yield url, False
        return
    async with EmbeddedBroker() as broker:
        yield broker.url, True
