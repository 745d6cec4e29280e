"""A broker that cannot be used is one line and exit 2, for ``odocan bridge`` and ``odocan fleet``:
refused, not authorized, TLS, DNS, no answer; an ACL denial is a warning line per topic; a broker
restart is "connection lost" / "reconnecting" / "reconnected", one line each, and no library noise.
"""

from __future__ import annotations

import asyncio
import contextlib
import getpass
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from odocan.host.cli.app import main
from odocan.host.mqtt import topics
from odocan.host.mqtt.broker import LOOPBACK, free_loopback_port
from tests.conftest_mqtt import (  # noqa: F401
    MOSQUITTO,
    Mosquitto,
    client,
    collect,
    mosquitto,
    restore_logging,
)

pytestmark = pytest.mark.usefixtures("restore_logging")  # no INFO handler left for later tests

COMMANDS = {
    "bridge": ["bridge", "-i", "virtual", "-c", f"test-connect-{os.getpid()}", "--duration", "5"],
    "fleet": ["fleet", "--robots", "2", "--duration", "5"],
}


@pytest.fixture
def silent_port() -> Iterator[int]:
    """A port that accepts TCP connections (the kernel's backlog) and never answers."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind((LOOPBACK, 0))
        sock.listen(8)
        yield sock.getsockname()[1]


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, list[str]]:
    code = main(argv)
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    assert "ExceptionGroup" not in err, err
    return code, err.splitlines()


def the_error(lines: list[str]) -> str:
    """The one line a refusal prints: beside warnings about the command line, nothing else (no
    banner naming a broker never reached)."""
    said = [line for line in lines if not line.startswith("warning:")]
    assert len(said) == 1, lines
    assert said[0].startswith("error:"), lines
    return said[0]


@pytest.mark.parametrize("command", COMMANDS)
@pytest.mark.parametrize(("broker", "expected"), [
    ("mqtt://u:s3cret@127.0.0.1:{free}", "cannot connect to mqtt://u@127.0.0.1:{free}: connection "
     "refused"),
    ("mqtts://u:s3cret@odocan-test.invalid",
     "cannot connect to mqtts://u@odocan-test.invalid:8883: DNS: the host name does not resolve"),
    ("mqtt://u:s3cret@127.0.0.1:{silent} --connect-timeout 0.5",
     "cannot connect to mqtt://u@127.0.0.1:{silent}: no answer within 0.5 s"),
    ("mqtts://127.0.0.1:{free} --ca /etc/passwd", "--ca /etc/passwd: not a usable CA certificate"),
    ("mqtt://127.0.0.1:{free} --connect-timeout 0", "--connect-timeout must be in (0, 300]"),
    ("mqtt://127.0.0.1:{free} --command-expiry -1", "--command-expiry must be in (0, 3600]"),
])
def test_an_unusable_broker_is_one_line_and_exit_2(
    command: str, broker: str, expected: str, silent_port: int,
    capsys: pytest.CaptureFixture[str],
) -> None:
    ports = {"free": free_loopback_port(), "silent": silent_port}
    url, *options = broker.format(**ports).split()
    code, lines = run_cli([*COMMANDS[command], "--broker", url, *options], capsys)
    assert code == 2
    assert expected.format(**ports) in the_error(lines)
    assert "s3cret" not in "\n".join(lines)


@pytest.mark.parametrize("command", COMMANDS)
@pytest.mark.parametrize(("user", "scheme", "expected"), [
    ("bridge:wrong", "mqtt", "not authorized (Not authorized)"),
    (None, "mqtt", "not authorized (Not authorized)"),
    ("bridge:bridge-pw", "mqtts", "TLS: the handshake failed; is this port TLS?"),
])
def test_mosquitto_refusals_are_one_line_and_exit_2(
    command: str, user: str | None, scheme: str, expected: str,
    mosquitto: Mosquitto,  # noqa: F811
    capsys: pytest.CaptureFixture[str],
) -> None:
    creds = f"{user}@" if user else ""
    url = f"{scheme}://{creds}127.0.0.1:{mosquitto.port}"
    code, lines = run_cli([*COMMANDS[command], "--broker", url], capsys)
    assert code == 2
    assert expected in the_error(lines)
    assert "wrong" not in "\n".join(lines)
    assert "bridge-pw" not in "\n".join(lines)


def test_acl_denials_are_one_warning_line_per_topic(
    mosquitto: Mosquitto,  # noqa: F811
    capsys: pytest.CaptureFixture[str],
) -> None:
    """robot001 may not publish its own status (the ACL lets it write commands only)."""
    url = f"mqtt://robot001:pw-001@127.0.0.1:{mosquitto.port}"
    argv = ["bridge", "-i", "virtual", "-c", f"test-acl-{os.getpid()}", "--duration", "2.5",
            "--name", "robot001", "--broker", url]
    code, lines = run_cli(argv, capsys)
    assert code == 0
    refusals = [line for line in lines if line.startswith("mqtt ") and "refused" in line]
    # status: online at the start, every second, offline at the end: refused each time, told once
    assert refusals == ["mqtt robot001: the broker refused a publication on odocan/robot001/status "
                        "(Not authorized)"]


def test_a_broker_restart_is_three_lines_and_no_library_noise(
    mosquitto: Mosquitto,  # noqa: F811
) -> None:
    """The bridge as a process (status and rates each second keep QoS-1 and QoS-0 traffic going)
    while the broker is away for a second."""

    async def scenario() -> str:
        url = mosquitto.url("bridge")
        bridge = subprocess.Popen(
            [sys.executable, "-m", "odocan", "bridge", "--name", "robot001", "-i", "virtual",
             "-c", f"test-restart-{os.getpid()}",
             "--broker", f"mqtt://bridge@127.0.0.1:{mosquitto.port}"],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
            env={**os.environ, "ODOCAN_MQTT_PASSWORD": "bridge-pw"},  # not in argv: no warning
        )
        try:
            await wait_status(url, "online")
            mosquitto.stop()
            await asyncio.sleep(1.0)  # the outage (not a proof of anything)
            mosquitto.start()
            await wait_status(url, "online", fresh=True)
        finally:
            bridge.send_signal(signal.SIGINT)
            _, err = bridge.communicate(timeout=20)
        assert bridge.returncode == 0, err
        return err

    err = asyncio.run(scenario())
    lines = err.splitlines()
    assert "Traceback" not in err, err
    assert "pending publish" not in err, err
    assert sum("robot001: connection lost" in line for line in lines) == 1, lines
    assert sum("robot001: reconnected to mqtt://bridge@127.0.0.1" in line for line in lines) == 1
    assert all(line.startswith(("bridge robot001:", "mqtt robot001: ")) for line in lines), lines


async def wait_status(url: object, state: str, *, fresh: bool = False) -> None:
    """Until ``odocan/robot001/status`` says ``state`` (``fresh``: not the retained copy)."""
    async with asyncio.timeout(30):
        while True:
            try:
                async with client(url) as sub:  # type: ignore[arg-type]
                    await sub.subscribe(topics.topic("robot001", "status"), qos=1)
                    async for message in sub.messages:
                        if fresh and message.retain:
                            continue
                        if f'"state":"{state}"'.encode() in message.payload:
                            return
            except Exception:  # the broker is not up yet
                await asyncio.sleep(0.1)



def _openssl(*args: str, cwd: Path) -> None:
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True)


def _ca(cwd: Path, name: str) -> None:
    _openssl("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", f"{name}.key",
             "-out", f"{name}.pem", "-days", "2", "-subj", f"/CN=odocan test {name}", cwd=cwd)


@pytest.fixture
def tls_mosquitto(tmp_path: Path) -> Iterator[tuple[int, Path, Path]]:
    """An anonymous mosquitto with a TLS listener: (port, its CA, another CA)."""
    if MOSQUITTO is None or shutil.which("openssl") is None:
        pytest.skip("mosquitto and openssl are needed (apt-get install mosquitto openssl)")
    _ca(tmp_path, "ca")
    _ca(tmp_path, "other")
    (tmp_path / "ext").write_text("subjectAltName=IP:127.0.0.1\n")
    _openssl("req", "-newkey", "rsa:2048", "-nodes", "-keyout", "server.key", "-out",
             "server.csr", "-subj", "/CN=127.0.0.1", cwd=tmp_path)
    _openssl("x509", "-req", "-in", "server.csr", "-CA", "ca.pem", "-CAkey", "ca.key",
             "-CAcreateserial", "-out", "server.pem", "-days", "2", "-extfile", "ext",
             cwd=tmp_path)
    port = free_loopback_port()
    conf = tmp_path / "tls.conf"
    conf.write_text(f"listener {port} {LOOPBACK}\nallow_anonymous true\n"
                    f"cafile {tmp_path / 'ca.pem'}\ncertfile {tmp_path / 'server.pem'}\n"
                    f"keyfile {tmp_path / 'server.key'}\nlog_dest none\n"
                    f"user {getpass.getuser()}\n")
    proc = subprocess.Popen([MOSQUITTO, "-c", str(conf)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            with contextlib.suppress(OSError):
                socket.create_connection((LOOPBACK, port), timeout=0.2).close()
                break
            time.sleep(0.02)
        yield port, tmp_path / "ca.pem", tmp_path / "other.pem"
    finally:
        proc.terminate()
        proc.wait(10)


def test_tls_with_the_right_ca_connects_and_with_another_is_one_line(
    tls_mosquitto: tuple[int, Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    port, ca, other = tls_mosquitto
    argv = [*COMMANDS["bridge"][:-1], "1", "--broker", f"mqtts://127.0.0.1:{port}"]
    code, lines = run_cli([*argv, "--ca", str(ca)], capsys)
    assert code == 0, lines
    assert lines[-1].startswith("bridge robot001: UNJUDGED: no firmware heard")  # a quiet bus
    assert lines[-2].startswith("bridge robot001: ")  # the summary, before the verdict
    assert "0 reconnects" in lines[-2]
    code, lines = run_cli([*argv, "--ca", str(other)], capsys)
    assert code == 2
    assert (f"cannot connect to mqtts://127.0.0.1:{port}: TLS: certificate verify failed"
            in the_error(lines))
