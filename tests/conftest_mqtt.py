"""Real brokers for the MQTT tests: mosquitto (password file + ACL) and the embedded amqtt.

``Mosquitto`` writes a configuration on a free 127.0.0.1 port with ``allow_anonymous false``, a
password file made by ``mosquitto_passwd -b`` and an ACL: user ``bridge`` may read and write
``odocan/#``; each robot's user (``robot001``, ``robot002``) may write only its own commands and
read only its own topics. Persistence is on, so a restart keeps sessions and queued messages;
``durable=True`` also saves them at every change (``autosave_on_changes``, ``autosave_interval
1``), so a broker killed with -9 keeps them too (``durable_mosquitto``).
Tests that need mosquitto skip with the reason when it is not installed.
"""

from __future__ import annotations

import asyncio
import getpass
import json
import logging
import shutil
import subprocess
import time
from collections.abc import AsyncIterator, Iterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import aiomqtt
import pytest

from odocan.host.mqtt.broker import LOOPBACK, BrokerURL, EmbeddedBroker, free_loopback_port
from odocan.host.mqtt.options import LIBRARY_LOGGERS, MQTT_LOGGERS
from tests.requires import require_executables

MOSQUITTO = shutil.which("mosquitto") or (
    "/usr/sbin/mosquitto" if Path("/usr/sbin/mosquitto").exists() else None
)
MOSQUITTO_PASSWD = shutil.which("mosquitto_passwd")
needs_mosquitto = pytest.mark.skipif(
    MOSQUITTO is None or MOSQUITTO_PASSWD is None,
    reason="mosquitto and mosquitto_passwd are not installed (apt-get install mosquitto)",
)
USERS = {"bridge": "bridge-pw", "robot001": "pw-001", "robot002": "pw-002"}
ACL = """\
user bridge
topic readwrite odocan/#

pattern write odocan/%u/cmd/#
pattern read odocan/%u/#
"""


class Mosquitto:
    """A mosquitto process on a free loopback port; ``restart`` keeps its port and its data."""

    def __init__(
        self,
        workdir: Path,
        *,
        users: dict[str, str] | None = None,
        acl: str = ACL,
        listener: str = "",
        durable: bool = False,
    ) -> None:
        """``users`` (default ``USERS``) and ``acl`` (default ``ACL``); ``listener``: more lines
        for the listener (e.g. its TLS settings); ``durable``: persist at every change."""
        assert MOSQUITTO is not None
        assert MOSQUITTO_PASSWD is not None
        self.port = free_loopback_port()
        self.dir = workdir
        self.users = USERS if users is None else users
        passwd = workdir / "passwd"
        passwd.touch()
        for user, password in self.users.items():
            subprocess.run([MOSQUITTO_PASSWD, "-b", str(passwd), user, password], check=True)
        (workdir / "acl").write_text(acl)
        self.conf = workdir / "mosquitto.conf"
        autosave = "autosave_on_changes true\nautosave_interval 1\n" if durable else ""
        self.conf.write_text(
            f"listener {self.port} {LOOPBACK}\n"
            f"{listener}"
            "allow_anonymous false\n"
            f"password_file {passwd}\n"
            f"acl_file {workdir / 'acl'}\n"
            "persistence true\n"
            f"persistence_location {workdir}/\n"
            f"{autosave}"
            "log_dest none\n"
            f"user {getpass.getuser()}\n"  # as root: keep the privileges to the tmp files
        )
        self.proc: subprocess.Popen[bytes] | None = None

    def url(self, user: str | None = "bridge") -> BrokerURL:
        """The broker as ``user`` (None: anonymous)."""
        password = self.users.get(user) if user else None
        return BrokerURL(host=LOOPBACK, port=self.port, username=user, password=password)

    def start(self) -> None:
        """Start and wait until the port accepts connections."""
        assert MOSQUITTO is not None  # as in __init__: the marker skips without it
        self.proc = subprocess.Popen([MOSQUITTO, "-c", str(self.conf)],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        deadline = time.monotonic() + 10
        import socket

        while time.monotonic() < deadline:
            try:
                socket.create_connection((LOOPBACK, self.port), timeout=0.2).close()
                return
            except OSError:
                if self.proc.poll() is not None:
                    err = self.proc.stderr.read().decode() if self.proc.stderr else ""
                    raise RuntimeError(f"mosquitto exited: {err}") from None
                time.sleep(0.02)
        raise RuntimeError("mosquitto did not start")

    def stop(self) -> None:
        """SIGTERM (mosquitto saves its persistence file) and wait."""
        if self.proc is not None:
            self.proc.terminate()
            self.proc.wait(timeout=10)
            self.proc = None


@pytest.fixture
def durable_mosquitto(tmp_path: Path) -> Iterator[Mosquitto]:
    """A running mosquitto that saves its state at every change: kill -9 loses none of it."""
    require_executables("mosquitto", "mosquitto_passwd", install="apt-get install mosquitto")
    broker = Mosquitto(tmp_path, durable=True)
    broker.start()
    try:
        yield broker
    finally:
        broker.stop()


@pytest.fixture
def mosquitto(tmp_path: Path) -> Iterator[Mosquitto]:
    """A running mosquitto with users and ACL (skips when not installed)."""
    require_executables("mosquitto", "mosquitto_passwd", install="apt-get install mosquitto")
    broker = Mosquitto(tmp_path)
    broker.start()
    try:
        yield broker
    finally:
        broker.stop()


@pytest.fixture
def restore_logging() -> Iterator[None]:
    """The CLI runs here (``configure_logging``, with ``--debug`` too) set the levels and
    handlers of odocan's and the libraries' loggers: put them back, so later tests' stderr
    holds no lines of ours."""
    loggers = [logging.getLogger(name) for name in ("odocan", *MQTT_LOGGERS, *LIBRARY_LOGGERS)]
    saved = [(lg, lg.level, list(lg.handlers), lg.propagate) for lg in loggers]
    yield
    for lg, level, handlers, propagate in saved:
        lg.setLevel(level)
        lg.handlers[:] = handlers
        lg.propagate = propagate


class Brokers:
    """One broker kind for parametrized tests: URLs for the bridge and for a robot's operator."""

    def __init__(self, kind: str, bridge: BrokerURL, operator: BrokerURL) -> None:
        self.kind, self.bridge, self.operator = kind, bridge, operator


@asynccontextmanager
async def broker_of(kind: str, tmp_path: Path) -> AsyncIterator[Brokers]:
    """``mosquitto`` (bridge user, robot001 as operator) or the embedded ``amqtt``."""
    if kind == "amqtt":
        async with EmbeddedBroker() as embedded:
            yield Brokers(kind, embedded.url, embedded.url)
        return
    require_executables("mosquitto", "mosquitto_passwd", install="apt-get install mosquitto")
    broker = Mosquitto(tmp_path)
    broker.start()
    try:
        yield Brokers(kind, broker.url("bridge"), broker.url("robot001"))
    finally:
        broker.stop()


def client(url: BrokerURL, **kwargs: Any) -> aiomqtt.Client:
    """An aiomqtt client of ``url``."""
    return aiomqtt.Client(**url.client_kwargs(), **kwargs)


async def collect(
    sub: aiomqtt.Client, until: Any, timeout_s: float = 10.0
) -> list[tuple[str, dict[str, Any]]]:
    """(topic, JSON) messages until ``until(messages)`` is true; TimeoutError otherwise."""
    got: list[tuple[str, dict[str, Any]]] = []
    async with asyncio.timeout(timeout_s):
        async for message in sub.messages:
            assert isinstance(message.payload, bytes)
            got.append((message.topic.value, json.loads(message.payload)))
            if until(got):
                return got
    return got
