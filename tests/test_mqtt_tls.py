"""TLS for real: mosquitto with a TLS listener that requires client certificates (TLS 1.2 at
least), a throw-away PKI (``tests.tls_certs``), and ``odocan bridge``, ``odocan fleet`` and
``odocan monitor --broker mqtts://`` connecting with ``--ca/--cert/--key`` and a password file.

Each way TLS can fail (wrong CA, expired server certificate, host name mismatch, no client
certificate, a server below TLS 1.2) ends with exit 2 and one ``error:`` line naming the reason;
``test_the_tls_failure_table`` prints the table (case -> exit code -> message) with ``-s``.
"""

from __future__ import annotations

import asyncio
import json
import os
import ssl
import threading
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from odocan.host.cli.app import main
from odocan.host.mqtt.broker import LOOPBACK, BrokerURL
from tests.conftest_mqtt import Mosquitto, client, restore_logging  # noqa: F401
from tests.fleet_watch_until import BOUND_S, end_watch_once
from tests.requires import require_executables
from tests.tls_certs import Pki, make_pki

pytestmark = pytest.mark.usefixtures("restore_logging")
PASSWORD = "tls-bridge-pw"


def tls_listener(pki: Pki, cert: Path) -> str:
    """mosquitto listener lines: our CA, ``cert`` as the server's, client certificates required,
    TLS 1.2 at least."""
    return (f"cafile {pki.ca}\ncertfile {cert}\nkeyfile {pki.server_key}\n"
            "require_certificate true\ntls_version tlsv1.2\n")


@dataclass
class TlsBrokers:
    """Three mosquitto TLS listeners: a good server certificate, an expired one, a wrong name."""

    pki: Pki
    good: Mosquitto
    expired: Mosquitto
    wrong_host: Mosquitto
    password_file: Path


@pytest.fixture(scope="module")
def tls(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TlsBrokers]:
    require_executables("mosquitto", "mosquitto_passwd", install="apt-get install mosquitto")
    root = tmp_path_factory.mktemp("tls")
    pki = make_pki(root / "pki")
    users = {"bridge": PASSWORD}
    brokers = []
    for name, cert in (("good", pki.server_cert), ("expired", pki.expired_cert),
                       ("wrong_host", pki.wrong_host_cert)):
        (root / name).mkdir()
        broker = Mosquitto(root / name, users=users, listener=tls_listener(pki, cert))
        broker.start()
        brokers.append(broker)
    password_file = root / "password"
    password_file.write_text(PASSWORD + "\n")
    password_file.chmod(0o600)
    try:
        good, expired, wrong_host = brokers
        yield TlsBrokers(pki, good, expired, wrong_host, password_file)
    finally:
        for broker in brokers:
            broker.stop()


def tls_url(broker: Mosquitto, pki: Pki, *, ca: Path | None = None,
            cert: bool = True) -> BrokerURL:
    return BrokerURL(host=LOOPBACK, port=broker.port, tls=True, username="bridge",
                     password=PASSWORD, ca=ca or pki.ca, cert=pki.client_cert if cert else None,
                     key=pki.client_key if cert else None)


def tls_args(tls: TlsBrokers, broker: Mosquitto, *, ca: Path | None = None,
             cert: bool = True) -> list[str]:
    """``--broker mqtts://bridge@127.0.0.1:PORT --ca --cert --key --password-file``."""
    args = ["--broker", f"mqtts://bridge@{LOOPBACK}:{broker.port}", "--ca", str(ca or tls.pki.ca),
            "--password-file", str(tls.password_file)]
    if cert:
        args += ["--cert", str(tls.pki.client_cert), "--key", str(tls.pki.client_key)]
    return args


def command(name: str, duration_s: str = "2") -> list[str]:
    if name == "bridge":
        return ["bridge", "--name", "tlsbot", "-i", "virtual", "-c", f"tls-{os.getpid()}",
                "--duration", duration_s, "--connect-timeout", "2"]
    if name == "fleet":
        return ["fleet", "-n", "1", "--duration", duration_s, "--connect-timeout", "2"]
    return ["monitor", "--json", "--duration", duration_s]


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(argv)
    out, err = capsys.readouterr()
    assert "Traceback" not in err, err
    assert "ExceptionGroup" not in err, err
    assert PASSWORD not in out + err
    return code, out, err


async def retained(url: BrokerURL, topic: str) -> dict[str, object]:
    """The retained JSON message on ``topic``, read over TLS."""
    async with client(url) as sub:
        await sub.subscribe(topic, qos=1)
        async with asyncio.timeout(5):
            async for message in sub.messages:
                assert isinstance(message.payload, bytes)
                data: dict[str, object] = json.loads(message.payload)
                return data
    raise AssertionError("no message")


def test_the_bridge_connects_over_tls_with_a_client_certificate(
    tls: TlsBrokers, capsys: pytest.CaptureFixture[str]
) -> None:
    code, _, err = run([*command("bridge"), *tls_args(tls, tls.good)], capsys)
    assert code == 0, err
    assert f"bridge tlsbot: mqtts://bridge@127.0.0.1:{tls.good.port}" in err
    status = asyncio.run(retained(tls_url(tls.good, tls.pki), "odocan/tlsbot/status"))
    assert status["state"] == "offline"
    assert status["reason"] == "bridge stopped"


def test_the_fleet_connects_over_tls_with_a_client_certificate(
    tls: TlsBrokers, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    report = tmp_path / "fleet.json"
    code, _, err = run([*command("fleet"), *tls_args(tls, tls.good), "--report", str(report),
                          "--max-miss-ratio", "1"], capsys)
    assert code == 0, err
    data = json.loads(report.read_text())
    assert data["broker"] == f"mqtts://bridge@127.0.0.1:{tls.good.port}"
    assert data["embedded_broker"] is False
    status = asyncio.run(retained(tls_url(tls.good, tls.pki), "odocan/robot001/status"))
    assert status["state"] == "offline"


def test_the_monitor_watches_a_fleet_over_tls(
    tls: TlsBrokers, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A status published over TLS (retained) shows in the monitor's table (the monitor ends
    once it has it: a 1.5 s watch, TLS handshake included, depended on the machine's load)."""
    end_watch_once(monkeypatch, lambda watch: "tlsview" in watch.table)

    async def publish() -> None:
        async with client(tls_url(tls.good, tls.pki)) as pub:
            body = json.dumps({"state": "online", "robot": "tlsview"})
            await pub.publish("odocan/tlsview/status", body, qos=1, retain=True)

    asyncio.run(publish())
    code, out, err = run([*command("monitor", BOUND_S), *tls_args(tls, tls.good)], capsys)
    assert code == 0, err
    model = json.loads(out)
    assert model["broker"] == f"mqtts://bridge@127.0.0.1:{tls.good.port}"
    assert model["robots"]["tlsview"]["online"] is True


FAILURES = {  # case -> (broker, --ca other than ours?, client certificate?, expected reason)
    "wrong CA": ("good", True, True,
                 "certificate verify failed: self-signed certificate in certificate chain: the "
                 "broker's certificate is not signed by the --ca given"),
    "expired server certificate": ("expired", False, True,
                                   "certificate verify failed: certificate has expired (the "
                                   "broker's certificate)"),
    "host name mismatch": ("wrong_host", False, True,
                           "hostname mismatch: the broker's certificate is not valid for this "
                           "host"),
    "no client certificate": ("good", False, False,
                              "the broker requires a client certificate (--cert/--key)"),
}


def failure(tls: TlsBrokers, name: str, case: str,
            capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    """Exit code and the one error line of ``name`` in the failure ``case``."""
    broker, wrong_ca, cert = FAILURES[case][:3]
    args = tls_args(tls, getattr(tls, broker), ca=tls.pki.other_ca if wrong_ca else None,
                    cert=cert)
    code, _, err = run([*command(name), *args], capsys)
    errors = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, err
    return code, errors[0]


@pytest.mark.parametrize("case", FAILURES)
@pytest.mark.parametrize("name", ["bridge", "fleet", "monitor"])
def test_a_tls_failure_is_exit_2_and_one_line_naming_the_reason(
    tls: TlsBrokers, name: str, case: str, capsys: pytest.CaptureFixture[str]
) -> None:
    code, line = failure(tls, name, case, capsys)
    assert code == 2
    assert line.startswith("error: cannot connect to mqtts://bridge@127.0.0.1:"), line
    assert f": TLS: {FAILURES[case][3]}" in line, line


def test_the_tls_failure_table(tls: TlsBrokers, capsys: pytest.CaptureFixture[str]) -> None:
    """The closing note's table, printed (``pytest -s``): case -> exit code -> message."""
    rows = [(case, *failure(tls, "bridge", case, capsys)) for case in FAILURES]
    with capsys.disabled():
        print("\n| case | exit | message (odocan bridge) |\n|---|---|---|")
        for case, code, line in rows:
            print(f"| {case} | {code} | {line} |")
    assert [code for _, code, _ in rows] == [2] * len(FAILURES)


def test_the_client_requires_tls_1_2(tls: TlsBrokers) -> None:
    """The client's context refuses anything below TLS 1.2, whatever the system allows."""
    context = tls_url(tls.good, tls.pki).tls_context()
    assert context.minimum_version == ssl.TLSVersion.TLSv1_2


def test_a_server_below_tls_1_2_is_refused(tls: TlsBrokers,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """A Python TLS server that speaks TLS 1.1 at most: the bridge does not go down to it."""
    server = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    server.load_cert_chain(tls.pki.server_cert, tls.pki.server_key)
    try:
        with warnings.catch_warnings():  # TLSv1_1 is deprecated: that is the point
            warnings.simplefilter("ignore", DeprecationWarning)
            server.minimum_version = server.maximum_version = ssl.TLSVersion.TLSv1_1
        server.set_ciphers("DEFAULT:@SECLEVEL=0")
    except (ValueError, ssl.SSLError) as exc:
        pytest.skip(f"this OpenSSL cannot serve TLS 1.1 ({exc})")
    handshakes: list[str] = []

    async def serve(ready: threading.Event, port: list[int], stop: asyncio.Event) -> None:
        async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            handshakes.append(str(writer.get_extra_info("ssl_object").version()))
            writer.close()

        srv = await asyncio.start_server(handle, LOOPBACK, 0, ssl=server)
        port.append(srv.sockets[0].getsockname()[1])
        ready.set()
        async with srv:
            await stop.wait()

    loop = asyncio.new_event_loop()
    stop, ready = asyncio.Event(), threading.Event()
    port: list[int] = []
    thread = threading.Thread(target=loop.run_until_complete, args=(serve(ready, port, stop),))
    thread.start()
    try:
        assert ready.wait(5)
        args = ["--broker", f"mqtts://bridge@{LOOPBACK}:{port[0]}", "--ca", str(tls.pki.ca),
                "--cert", str(tls.pki.client_cert), "--key", str(tls.pki.client_key)]
        code, _, err = run([*command("bridge"), *args], capsys)
    finally:
        loop.call_soon_threadsafe(stop.set)
        thread.join(5)
    assert code == 2
    assert handshakes == []  # no TLS 1.1 session was ever made
    line = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(line) == 1, err
    assert ": TLS: " in line[0], err
    assert "TLS 1.2 or later" in line[0]


@pytest.mark.parametrize("name", ["bridge", "fleet", "monitor"])
@pytest.mark.parametrize(("case", "expected"), [
    ("ca not PEM", "--ca {junk}: not a usable CA certificate"),
    ("cert not PEM", "--cert {junk} / --key {key}: not a usable certificate and key"),
    ("key of another certificate", "--cert {cert} / --key {server_key}: not a usable certificate "
     "and key"),
    ("cert without key", "--cert and --key go together"),
])
def test_bad_tls_files_are_one_line_before_any_connection(
    name: str, case: str, expected: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Port 1: nothing listens there, so the line can only come from the files."""
    pki = make_pki(tmp_path / "pki")
    junk = tmp_path / "junk.pem"
    junk.write_text("not a certificate\n")
    files = {"junk": junk, "key": pki.client_key, "cert": pki.client_cert,
             "server_key": pki.server_key}
    ca, cert, key = {
        "ca not PEM": (junk, pki.client_cert, pki.client_key),
        "cert not PEM": (pki.ca, junk, pki.client_key),
        "key of another certificate": (pki.ca, pki.client_cert, pki.server_key),
        "cert without key": (pki.ca, pki.client_cert, None),
    }[case]
    args = ["--broker", f"mqtts://{LOOPBACK}:1", "--ca", str(ca), "--cert", str(cert)]
    args += ["--key", str(key)] if key else []
    code, _, err = run([*command(name), *args], capsys)
    assert code == 2
    (line,) = err.splitlines()
    assert line.startswith(f"error: {expected.format(**files)}"), line
