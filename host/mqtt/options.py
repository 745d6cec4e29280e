"""Command-line options shared by ``odocan bridge`` and ``odocan fleet``, the broker to use, and
where the MQTT side's log lines go (``configure_logging``)."""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

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
    group.add_argument(
        "--connect-timeout", type=float, default=5.0, metavar="SECONDS",
        help="give up when the first connection to the broker takes longer (default: 5)",
    )
    group.add_argument(
        "--command-expiry", type=float, default=5.0, metavar="SECONDS",
        help="a command without its own MQTT v5 message expiry is refused ('expired') when "
        "older than this (default: 5)",
    )


def broker_url(args: argparse.Namespace) -> BrokerURL | None:
    """The ``--broker`` given (None: embedded); checks the TLS files exist."""
    for name in ("ca", "cert", "key"):
        path = getattr(args, name, None)
        if path is not None and not path.is_file():
            raise ConfigurationError(f"--{name} {path}: no such file")
    if not 0 < args.publish_hz <= 1000:
        raise ConfigurationError(f"--publish-hz must be in (0, 1000], got {args.publish_hz}")
    if not 0 < args.connect_timeout <= 300:
        raise ConfigurationError(
            f"--connect-timeout must be in (0, 300] s, got {args.connect_timeout}")
    if not 0 < args.command_expiry <= 3600:
        raise ConfigurationError(
            f"--command-expiry must be in (0, 3600] s, got {args.command_expiry}")
    if args.broker is None:
        if args.ca or args.cert or args.key:
            raise ConfigurationError("--ca/--cert/--key need --broker mqtts://...")
        return None
    url = BrokerURL.parse(args.broker, ca=args.ca, cert=args.cert, key=args.key)
    if url.tls:
        url.tls_context()  # a bad --ca/--cert/--key is one line now, not at connect time
    return url


def bridge_options(args: argparse.Namespace) -> dict[str, Any]:
    """The bridge's settings given on the command line (``BridgeConfig``/``FleetRun`` keys)."""
    return {
        "publish_hz": args.publish_hz,
        "client_prefix": args.client_prefix,
        "connect_timeout_s": args.connect_timeout,
        "command_expiry_s": args.command_expiry,
    }


# asyncio too: aiomqtt's socket callbacks race a closing socket now and then ("Bad file descriptor")
LIBRARY_LOGGERS = ("aiomqtt", "mqtt", "paho", "amqtt", "transitions", "asyncio",
                   "odocan.mqtt.client")


class _StderrHandler(logging.StreamHandler):  # type: ignore[type-arg]
    """The handler ``configure_logging`` installs (found again to be replaced); writes to the
    ``sys.stderr`` of the moment (pytest's capture swaps it)."""

    def emit(self, record: logging.LogRecord) -> None:
        self.stream = sys.stderr  # not setStream: it would flush the old one, maybe closed
        super().emit(record)


def configure_logging(debug: bool) -> None:
    """odocan's MQTT lines (connection lost / reconnecting / reconnected, refusals) on stderr,
    one line each; the libraries' (amqtt, aiomqtt, paho) only with ``--debug``."""
    handler = _StderrHandler()
    handler.setFormatter(logging.Formatter("%(levelname)s: %(message)s" if debug
                                           else "mqtt %(message)s"))
    odocan = logging.getLogger("odocan")
    for name in ("odocan", *LIBRARY_LOGGERS):  # once per process, even when called again
        old = logging.getLogger(name)
        for h in [h for h in old.handlers if isinstance(h, _StderrHandler)]:
            old.removeHandler(h)
    odocan.addHandler(handler)
    odocan.setLevel(logging.DEBUG if debug else logging.INFO)
    odocan.propagate = False
    for name in LIBRARY_LOGGERS:
        logger = logging.getLogger(name)
        logger.setLevel(logging.DEBUG if debug else logging.CRITICAL)
        if debug and name != "odocan.mqtt.client":
            logger.addHandler(handler)


@asynccontextmanager
async def broker_for(url: BrokerURL | None) -> AsyncIterator[tuple[BrokerURL, bool]]:
    """``(url, embedded)``: ``url`` itself, or an embedded broker for the duration."""
    if url is not None:
        yield url, False
        return
    async with EmbeddedBroker() as broker:
        yield broker.url, True
