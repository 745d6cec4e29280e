"""Where the broker is: ``--broker`` URLs, TLS files, and the embedded amqtt broker.

``mqtt://user:pass@host:port`` (default port 1883) or ``mqtts://...`` (default 8883, with
``--ca``/``--cert``/``--key``). Without ``--broker`` the commands start ``EmbeddedBroker``: an
in-process amqtt broker on a free loopback port (127.0.0.1 only), anonymous access, so ``odocan
bridge`` and ``odocan fleet`` work on a fresh machine.
"""

from __future__ import annotations

import asyncio
import logging
import socket
from dataclasses import dataclass, replace
from pathlib import Path
from types import TracebackType
from typing import Any
from urllib.parse import unquote, urlsplit

import aiomqtt

from odocan.sim.exceptions import ConfigurationError

LOOPBACK = "127.0.0.1"
_DEFAULT_PORTS = {"mqtt": 1883, "mqtts": 8883}


@dataclass(frozen=True)
class BrokerURL:
    """A broker address and credentials (``mqtt[s]://[user[:pass]@]host[:port]``)."""

    host: str
    port: int
    tls: bool = False
    username: str | None = None
    password: str | None = None
    ca: Path | None = None
    cert: Path | None = None
    key: Path | None = None

    @classmethod
    def parse(
        cls,
        url: str,
        *,
        ca: Path | None = None,
        cert: Path | None = None,
        key: Path | None = None,
    ) -> BrokerURL:
        """Parse ``url``; a one-line ``ConfigurationError`` when it is not a broker URL."""
        parts = urlsplit(url)
        if parts.scheme not in _DEFAULT_PORTS:
            raise ConfigurationError(f"--broker {url!r}: expected mqtt://host[:port] or mqtts://")
        if not parts.hostname:
            raise ConfigurationError(f"--broker {url!r}: no host")
        if parts.path not in ("", "/") or parts.query or parts.fragment:
            raise ConfigurationError(f"--broker {url!r}: unexpected path or query")
        try:
            port = parts.port or _DEFAULT_PORTS[parts.scheme]
        except ValueError as exc:
            raise ConfigurationError(f"--broker {url!r}: {exc}") from None
        tls = parts.scheme == "mqtts"
        if not tls and (ca or cert or key):
            raise ConfigurationError("--ca/--cert/--key need an mqtts:// broker")
        if (cert is None) != (key is None):
            raise ConfigurationError("--cert and --key go together")
        return cls(
            host=parts.hostname,
            port=port,
            tls=tls,
            username=unquote(parts.username) if parts.username else None,
            password=unquote(parts.password) if parts.password else None,
            ca=ca,
            cert=cert,
            key=key,
        )

    def with_credentials(self, username: str | None, password: str | None) -> BrokerURL:
        """The same broker with other credentials."""
        return replace(self, username=username, password=password)

    def client_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of ``aiomqtt.Client`` for this broker (host, port, auth, TLS)."""
        kwargs: dict[str, Any] = {
            "hostname": self.host,
            "port": self.port,
            "username": self.username,
            "password": self.password,
        }
        if self.tls:
            kwargs["tls_params"] = aiomqtt.TLSParameters(
                ca_certs=str(self.ca) if self.ca else None,
                certfile=str(self.cert) if self.cert else None,
                keyfile=str(self.key) if self.key else None,
            )
        return kwargs

    def __str__(self) -> str:
        """The URL without the password."""
        user = f"{self.username}@" if self.username else ""
        return f"{'mqtts' if self.tls else 'mqtt'}://{user}{self.host}:{self.port}"


def free_loopback_port() -> int:
    """A TCP port free on 127.0.0.1 right now (the OS's choice)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind((LOOPBACK, 0))
        port: int = sock.getsockname()[1]
        return port


class EmbeddedBroker:
    """An amqtt broker in this process on ``127.0.0.1:<free port>``, anonymous access.

    ``async with EmbeddedBroker() as broker:`` then ``broker.url`` (a ``BrokerURL``).
    """

    def __init__(self, *, port: int | None = None) -> None:
        self.port = port or free_loopback_port()
        self.url = BrokerURL(host=LOOPBACK, port=self.port)
        self._broker: Any = None

    def _config(self) -> dict[str, Any]:
        return {
            "listeners": {"default": {"type": "tcp", "bind": f"{LOOPBACK}:{self.port}"}},
            "plugins": {"amqtt.plugins.authentication.AnonymousAuthPlugin": {
                "allow_anonymous": True
            }},
        }

    async def start(self) -> None:
        """Start listening."""
        from amqtt.broker import Broker  # heavy import: only when the broker is wanted

        for name in ("amqtt", "transitions"):
            logging.getLogger(name).setLevel(logging.WARNING)
        self._broker = Broker(self._config())
        await self._broker.start()

    async def stop(self) -> None:
        """Disconnect every client and stop listening."""
        if self._broker is not None:
            broker, self._broker = self._broker, None
            await broker.shutdown()
            await asyncio.sleep(0)

    async def __aenter__(self) -> EmbeddedBroker:
        await self.start()
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.stop()
