"""Where the broker is: ``--broker`` URLs, TLS files, and the embedded amqtt broker.

``mqtt://user:pass@host:port`` (default port 1883) or ``mqtts://...`` (default 8883, with
``--ca``/``--cert``/``--key``, loaded into an ``ssl.SSLContext`` up front so a bad file is one
line before any connection). Without ``--broker`` the commands start ``EmbeddedBroker``: an
in-process amqtt broker on a free loopback port (127.0.0.1 only), anonymous access, so ``odocan
bridge`` and ``odocan fleet`` work on a fresh machine. amqtt speaks MQTT 3.1.1 only, so its URL
says ``v5=False``; any other broker is tried with MQTT v5 first (reason codes, message expiry).

``BrokerError`` is a broker that cannot be used (``connect_failure`` names the reason: refused,
not authorized, TLS, DNS, no answer); the CLI prints it as one line and exits 2.
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import logging
import re
import socket
import ssl
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import TracebackType
from typing import Any
from urllib.parse import unquote, urlsplit

from aiomqtt.exceptions import MqttConnectError

from odocan.sim.exceptions import ConfigurationError, OdocanError

LOOPBACK = "127.0.0.1"
_DEFAULT_PORTS = {"mqtt": 1883, "mqtts": 8883}


@dataclass(frozen=True)
class BrokerURL:
    """A broker address and credentials (``mqtt[s]://[user[:pass]@]host[:port]``)."""

    host: str
    port: int
    tls: bool = False
    username: str | None = None
    password: str | None = field(default=None, repr=False)  # never in a repr or a traceback
    ca: Path | None = None
    cert: Path | None = None
    key: Path | None = None
    v5: bool = True  # False: a broker known to speak MQTT 3.1.1 only (the embedded amqtt)

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
        try:
            parts = urlsplit(url)
        except ValueError as exc:  # e.g. 'mqtt://[::1' (an unclosed IPv6 bracket)
            raise ConfigurationError(f"--broker {url!r}: {exc}") from None
        if parts.scheme not in _DEFAULT_PORTS:
            raise ConfigurationError(f"--broker {url!r}: expected mqtt://host[:port] or mqtts://")
        if not parts.hostname:
            raise ConfigurationError(f"--broker {url!r}: no host")
        if parts.path not in ("", "/") or parts.query or parts.fragment:
            raise ConfigurationError(f"--broker {url!r}: unexpected path or query")
        try:
            port = parts.port
        except ValueError as exc:
            raise ConfigurationError(f"--broker {url!r}: {exc}") from None
        if port == 0:  # no broker listens there ('mqtts://h:0' was taken as h:8883)
            raise ConfigurationError(f"--broker {url!r}: port 0 (give 1..65535, or none)")
        port = port or _DEFAULT_PORTS[parts.scheme]
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
            kwargs["tls_context"] = self.tls_context()
        return kwargs

    def tls_context(self) -> ssl.SSLContext:
        """The TLS context of ``--ca``/``--cert``/``--key``; ``ConfigurationError`` naming the
        file that is not a usable PEM certificate or key."""
        try:
            context = ssl.create_default_context(cafile=str(self.ca) if self.ca else None)
        except (ssl.SSLError, OSError) as exc:
            raise ConfigurationError(
                f"--ca {self.ca}: not a usable CA certificate ({exc})"
            ) from None
        context.minimum_version = ssl.TLSVersion.TLSv1_2  # whatever the system's default
        if self.cert is not None:
            try:
                context.load_cert_chain(str(self.cert), str(self.key) if self.key else None)
            except (ssl.SSLError, OSError) as exc:
                raise ConfigurationError(
                    f"--cert {self.cert} / --key {self.key}: not a usable certificate and key "
                    f"({exc})"
                ) from None
        return context

    def __str__(self) -> str:
        """The URL without the password."""
        user = f"{self.username}@" if self.username else ""
        return f"{'mqtts' if self.tls else 'mqtt'}://{user}{self.host}:{self.port}"


class BrokerError(OdocanError):
    """The broker cannot be used: no connection, or it refused us (one line, password redacted)."""


_NOT_AUTHORIZED = frozenset({4, 5, 0x86, 0x87})  # 3.1.1 and v5 CONNACK codes
_DNS_HINTS = ("name or service not known", "temporary failure in name resolution",
              "nodename nor servname", "no address associated")


def connect_failure(
    exc: BaseException, timeout_s: float, *, tls: bool = False, client_cert: bool = True
) -> str:
    """Why a connection attempt failed, in a few words: refused, not authorized, TLS, DNS ...
    (``tls``: a reset or EOF during the handshake is most likely a port without TLS;
    ``client_cert``: whether we offered one, to tell a broker that wants one)."""
    if isinstance(exc, MqttConnectError):
        code = getattr(exc.rc, "value", exc.rc)
        what = "not authorized" if code in _NOT_AUTHORIZED else "refused by the broker"
        return f"{what} ({exc.rc})"
    if isinstance(exc, TimeoutError):
        return f"no answer within {timeout_s:g} s (--connect-timeout)"
    text = str(exc) or type(exc).__name__
    low = text.lower()
    if "refused" in low:
        return "connection refused"
    if any(hint in low for hint in _DNS_HINTS) or isinstance(exc, socket.gaierror):
        return f"DNS: the host name does not resolve ({text})"
    if "ssl" in low or "certificate" in low or "tls" in low:
        return f"TLS: {tls_reason(text, client_cert=client_cert)}"
    if tls and ("reset" in low or "eof" in low):
        return f"TLS: the handshake failed; is this port TLS? ({text})"
    if "timed out" in low:
        return f"no answer within {timeout_s:g} s (--connect-timeout)"
    return text


_SSL_NOISE = re.compile(r"^\[SSL: [A-Z0-9_]+\] |\s*\(_ssl\.c:\d+\)$")


def tls_reason(text: str, *, client_cert: bool) -> str:
    """An OpenSSL message as a reason a person acts on: whose certificate, what is wrong, which
    option to look at (``--ca``, ``--cert/--key``)."""
    text = _SSL_NOISE.sub("", text.strip())
    low = text.lower()
    if "mismatch" in low:  # "Hostname mismatch" / "IP address mismatch, not valid for 'x'"
        return (f"hostname mismatch: the broker's certificate is not valid for this host "
                f"({text})")
    if "has expired" in low or "not yet valid" in low:
        return f"{text} (the broker's certificate)"
    if "self-signed certificate" in low or "unable to get local issuer" in low:
        return f"{text}: the broker's certificate is not signed by the --ca given"
    if "certificate required" in low or ("handshake failure" in low and not client_cert):
        return "the broker requires a client certificate (--cert/--key)"
    if "unknown ca" in low or "bad certificate" in low or "certificate unknown" in low:
        return f"the broker rejected our client certificate (--cert) ({text})"
    if "unsupported protocol" in low or "protocol version" in low:
        return f"no common TLS version (odocan requires TLS 1.2 or later) ({text})"
    if "eof occurred" in low:
        return ("the broker closed the connection during the TLS handshake (a port without TLS, "
                "or no TLS version in common: odocan requires TLS 1.2 or later)")
    return text


_ALERT_WAIT_S = 1.0  # after our handshake: a broker that refuses us says so at once


async def tls_diagnosis(broker: BrokerURL, timeout_s: float) -> str | None:
    """Why TLS to ``broker`` fails, from a bare handshake, or None when TLS itself works.

    With TLS 1.3 a broker that wants a client certificate says so (an alert) only after the
    client's side of the handshake has finished: paho then waits for a CONNACK that never
    comes. Here, after the handshake, we listen (sending nothing) for up to a second: an MQTT
    broker that accepted us waits for our CONNECT in silence; one that refused us sends the
    alert, or closes."""
    closed = ("the broker closed the connection after the TLS handshake (does it require a "
              "client certificate?)" if broker.cert is None else None)
    try:
        async with asyncio.timeout(timeout_s):
            reader, writer = await asyncio.open_connection(
                broker.host, broker.port, ssl=broker.tls_context(),
                server_hostname=broker.host)
        try:
            async with asyncio.timeout(_ALERT_WAIT_S):
                return closed if not await reader.read(1) else None
        except TimeoutError:
            return None  # silence: TLS is up, the broker waits for a CONNECT
        except (ssl.SSLError, ssl.CertificateError):
            raise
        except OSError:  # reset after the handshake: refused without an alert we could read
            return closed
        finally:
            writer.close()
            with contextlib.suppress(Exception):
                await writer.wait_closed()
    except (ssl.SSLError, ssl.CertificateError) as exc:
        return tls_reason(str(exc), client_cert=broker.cert is not None)
    except (OSError, TimeoutError, ConfigurationError):
        return None


async def first_connect_failure(exc: BaseException, broker: BrokerURL, timeout_s: float) -> str:
    """``connect_failure`` of a first connection; for TLS, when that says only "no answer" or
    "connection lost", what a bare TLS handshake learns instead (``tls_diagnosis``)."""
    reason = connect_failure(exc, timeout_s, tls=broker.tls, client_cert=broker.cert is not None)
    if broker.tls and not reason.startswith(("TLS:", "not authorized", "DNS", "connection ref")):
        found = await tls_diagnosis(broker, timeout_s)
        if found is not None:
            return f"TLS: {found}"
    return reason


def protocol_unsupported(exc: BaseException) -> bool:
    """A CONNACK saying the broker does not speak the MQTT version we asked for (e.g. v5)."""
    if not isinstance(exc, MqttConnectError):
        return False
    return getattr(exc.rc, "value", exc.rc) in (1, 0x84)


def first_error(group: BaseExceptionGroup[BaseException]) -> BaseException:
    """The first ``OdocanError`` inside ``group`` (a TaskGroup's), else ``group`` itself."""
    for exc in group.exceptions:
        if isinstance(exc, BaseExceptionGroup):
            inner = first_error(exc)
            if inner is not exc:
                return inner
        elif isinstance(exc, OdocanError):
            return exc
    return group


def free_loopback_port() -> int:
    """A TCP port free on 127.0.0.1 right now (the OS's choice)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind((LOOPBACK, 0))
        port: int = sock.getsockname()[1]
        return port


def check_embedded_bind(bind: str) -> None:
    """``ConfigurationError`` unless ``bind`` is a loopback address (127.0.0.0/8, ::1,
    localhost): the embedded broker has no credentials and no TLS, so it serves this machine
    only."""
    try:
        loopback = bind == "localhost" or ipaddress.ip_address(bind).is_loopback
    except ValueError:
        loopback = False
    if not loopback:
        raise ConfigurationError(
            f"the embedded broker lets anyone in (no users, no TLS): it listens on loopback "
            f"only, not on {bind!r}; to serve other machines run a broker with users, ACLs and "
            f"TLS and give it with --broker")


class EmbeddedBroker:
    """An amqtt broker in this process on ``127.0.0.1:<free port>``, anonymous access.

    ``async with EmbeddedBroker() as broker:`` then ``broker.url`` (a ``BrokerURL``).
    """

    def __init__(self, *, port: int | None = None, bind: str = LOOPBACK) -> None:
        """``bind``: the address to listen on; anything but loopback is refused
        (``ConfigurationError``), for this broker lets anyone in (no users, no TLS)."""
        check_embedded_bind(bind)
        self.port = port or free_loopback_port()
        self.url = BrokerURL(host=LOOPBACK, port=self.port, v5=False)  # amqtt: 3.1.1 only
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
            logger = logging.getLogger(name)
            if logger.level == logging.NOTSET:  # the CLI may have chosen (--debug)
                logger.setLevel(logging.CRITICAL)
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


def session_lost(robot: str, away_s: float, expiry_s: float) -> str:
    """Why a broker we reconnected to after ``away_s`` lacks our session of ``expiry_s``: it
    lost its state (restarted without its persistence: a mosquitto started as root writes its
    database as user mosquitto, and a directory it cannot write keeps none), or it closed our
    connection well before we saw it go (a bridge stalled past 1.5 keepalives, then its session
    expired meanwhile: ``away_s`` counts from when we saw the loss), or it keeps sessions for
    less than we asked. The line names them all: it is true whichever happened."""
    return (f"{robot}: the broker no longer had this bridge's session after {away_s:.1f} s "
            f"away (expiry {expiry_s:g} s): it lost its state (restarted without its "
            "persistence?), dropped the connection earlier than the bridge saw (a stall), or "
            "keeps sessions for less; commands and results it held may be lost")
