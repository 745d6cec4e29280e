"""Command-line options shared by ``odocan bridge`` and ``odocan fleet`` (and the credentials by
``odocan monitor --broker``), the broker to use, and where the MQTT side's log lines go
(``configure_logging``).

Secrets stay out of argv: the password comes from ``--password-file`` (first line) or the
environment variable ``ODOCAN_MQTT_PASSWORD``; one in the URL still works, with a warning.
"""

from __future__ import annotations

import argparse
import logging
import os
import stat
import sys
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

from odocan.host.mqtt.broker import LOOPBACK, BrokerURL, EmbeddedBroker, check_embedded_bind
from odocan.host.mqtt.clientids import DEFAULT_PREFIX
from odocan.sim.exceptions import ConfigurationError

PASSWORD_ENV = "ODOCAN_MQTT_PASSWORD"


def add_mqtt_arguments(parser: argparse.ArgumentParser) -> None:
    """``--broker``, TLS and password options, ``--listen``, ``--publish-hz``,
    ``--client-prefix``, ``--connect-timeout``, ``--command-expiry``."""
    group = parser.add_argument_group("MQTT (without --broker: an embedded amqtt broker)")
    group.add_argument(
        "--broker", metavar="URL",
        help="mqtt://[user:pass@]host[:port] or mqtts://... (default: start an embedded broker "
        "on a free 127.0.0.1 port)",
    )
    add_broker_credentials(group)
    group.add_argument(
        "--listen", default=LOOPBACK, metavar="ADDR",
        help="address of the embedded broker: loopback only, since it lets anyone in "
        "(default: %(default)s)",
    )
    group.add_argument(
        "--publish-hz", type=float, default=10.0, metavar="HZ",
        help="pose/reference/error publications per robot and second (default: 10)",
    )
    group.add_argument(
        "--client-prefix", default=DEFAULT_PREFIX,
        help="MQTT client ids are PREFIX<robot> when both are 0-9a-zA-Z and fit MQTT 3.1.1's 23 "
        "bytes, else a stable 23-byte form of letters and digits (persistent sessions; "
        "default: %(default)s)",
    )
    group.add_argument(
        "--connect-timeout", type=float, default=5.0, metavar="SECONDS",
        help="give up when the first connection to the broker takes longer (default: 5)",
    )
    group.add_argument(
        "--command-expiry", type=float, default=5.0, metavar="SECONDS",
        help="a command without its own MQTT v5 message expiry is refused ('expired') when "
        "older than this since it arrived, and one with sent_unix_s when sent longer ago "
        "(default: 5)",
    )


def add_broker_credentials(group: argparse._ArgumentGroup) -> None:
    """``--ca``, ``--cert``, ``--key`` (TLS) and ``--password-file`` (or ODOCAN_MQTT_PASSWORD)."""
    group.add_argument("--ca", type=Path, help="CA certificate (PEM) that signed the broker's, "
                       "for mqtts:// (default: the system's CAs)")
    group.add_argument("--cert", type=Path, help="client certificate (PEM) for mqtts://")
    group.add_argument("--key", type=Path, help="client key (PEM) for mqtts://")
    group.add_argument(
        "--password-file", type=Path, metavar="PATH",
        help=f"the MQTT password: the first line of PATH (mode 600), for the user in "
        f"--broker mqtt://USER@host; or set {PASSWORD_ENV}. A password in the URL works but "
        "other users of the machine see it (ps, shell history)",
    )


def check_tls_files(args: argparse.Namespace) -> None:
    """``ConfigurationError`` naming a ``--ca/--cert/--key`` that is not a file."""
    for name in ("ca", "cert", "key"):
        path = getattr(args, name, None)
        if path is not None and not path.is_file():
            raise ConfigurationError(f"--{name} {path}: no such file")


def with_password(url: BrokerURL, args: argparse.Namespace) -> BrokerURL:
    """``url`` with the password of ``--password-file`` or ``$ODOCAN_MQTT_PASSWORD`` (in that
    order); a password in the URL itself is used, with one warning on stderr that it is visible
    to other users. ``ConfigurationError`` (one line, naming the path) when the file cannot be
    read, is empty, or comes with a password in the URL too."""
    path: Path | None = getattr(args, "password_file", None)
    if url.password is not None:
        if path is not None:
            raise ConfigurationError(
                "--broker carries a password and --password-file gives one: give only one")
        print("warning: the password in --broker is visible to other users of this machine "
              f"(ps, shell history): use --password-file or {PASSWORD_ENV}", file=sys.stderr)
        return url
    if path is not None:
        password = read_password_file(path)
    elif os.environ.get(PASSWORD_ENV):
        password = os.environ[PASSWORD_ENV]
    else:
        return url
    if url.username is None:
        source = "--password-file" if path is not None else PASSWORD_ENV
        raise ConfigurationError(
            f"{source}: a password needs a user name in --broker (mqtt://USER@host)")
    return url.with_credentials(url.username, password)


MAX_PASSWORD_BYTES = 65535  # MQTT's limit for a password (a two-byte length)


def read_password_file(path: Path) -> str:
    """The first line of ``path``; a warning when others than its owner may read it;
    ``ConfigurationError`` naming ``path`` when it cannot be read or is empty."""
    try:
        mode = path.stat().st_mode
        if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):  # a directory: open() says so
            raise ConfigurationError(  # before reading: /dev/zero has no first line, ever
                f"--password-file {path}: not a regular file")
        with path.open("rb") as file:
            text = file.readline(MAX_PASSWORD_BYTES + 1).decode("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        why = exc.strerror if isinstance(exc, OSError) and exc.strerror else "not UTF-8 text"
        raise ConfigurationError(f"--password-file {path}: cannot read it ({why})") from None
    if len(text.rstrip("\r\n")) > MAX_PASSWORD_BYTES:
        raise ConfigurationError(
            f"--password-file {path}: first line longer than {MAX_PASSWORD_BYTES} bytes")
    password = text.splitlines()[0] if text else ""
    if not password:
        raise ConfigurationError(f"--password-file {path}: empty first line")
    if mode & 0o077:
        print(f"warning: --password-file {path} may be read by other users (mode "
              f"{stat.S_IMODE(mode):03o}): chmod 600 {path}", file=sys.stderr)
    return password


def broker_url(args: argparse.Namespace) -> BrokerURL | None:
    """The ``--broker`` given (None: embedded), with its password (``with_password``); checks
    the TLS files exist and ``--listen`` is loopback."""
    check_tls_files(args)
    check_embedded_bind(args.listen)
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
        if args.password_file:
            raise ConfigurationError("--password-file needs --broker mqtt://USER@host")
        return None
    if args.listen != LOOPBACK:
        raise ConfigurationError("--listen is the embedded broker's: not with --broker")
    url = with_password(BrokerURL.parse(args.broker, ca=args.ca, cert=args.cert, key=args.key),
                        args)
    if url.tls:
        url.tls_context()  # a bad --ca/--cert/--key is one line now, not at connect time
    return url


def monitor_broker_url(args: argparse.Namespace) -> BrokerURL:
    """``odocan monitor --broker URL`` with its TLS files and password (``with_password``)."""
    check_tls_files(args)
    url = with_password(BrokerURL.parse(args.mqtt, ca=args.ca, cert=args.cert, key=args.key),
                        args)
    if url.tls:
        url.tls_context()
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


MQTT_LOGGERS = ("odocan.mqtt", "odocan.host.mqtt")  # the link's and the bridge's own lines


def configure_logging(debug: bool) -> None:
    """odocan's MQTT lines (connection lost / reconnecting / reconnected, refusals) on stderr,
    one line each; the rest of odocan (e.g. the fault injector's per-frame lines) and the
    libraries' (amqtt, aiomqtt, paho) only with ``--debug``."""
    handler = _StderrHandler()
    handler.setFormatter(logging.Formatter("%(levelname)s: %(message)s" if debug
                                           else "mqtt %(message)s"))
    for name in ("odocan", *MQTT_LOGGERS, *LIBRARY_LOGGERS):  # once per process, even if again
        old = logging.getLogger(name)
        for h in [h for h in old.handlers if isinstance(h, _StderrHandler)]:
            old.removeHandler(h)
    for name in ("odocan",) if debug else MQTT_LOGGERS:
        ours = logging.getLogger(name)
        ours.addHandler(handler)
        ours.setLevel(logging.DEBUG if debug else logging.INFO)
        ours.propagate = False
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
