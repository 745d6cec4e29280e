"""Secrets out of argv: the MQTT password from ``--password-file`` or ``ODOCAN_MQTT_PASSWORD``;
one in the URL still works but warns once; a group/world-readable file warns; an unreadable one
is exit 2 and one line naming its path. A distinctive password never shows in any artefact of
a run (stdout, stderr with ``--debug``, the ``--report`` JSON, every file the run wrote), on
success or on refusal.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from pathlib import Path

import pytest

from odocan.host.cli.app import main
from odocan.host.mqtt.broker import LOOPBACK, BrokerURL
from odocan.host.mqtt.options import PASSWORD_ENV
from tests.conftest_mqtt import Mosquitto, restore_logging  # noqa: F401
from tests.fleet_watch_until import BOUND_S, end_watch_once
from tests.requires import require_executables

pytestmark = pytest.mark.usefixtures("restore_logging")
SECRET = "Zq7-odocan-SECRET-42"  # distinctive: found anywhere means leaked


@pytest.fixture
def broker(tmp_path: Path) -> Iterator[Mosquitto]:
    """mosquitto where user ``bridge`` has the password ``SECRET`` (and ``odocan/#``)."""
    require_executables("mosquitto", "mosquitto_passwd", install="apt-get install mosquitto")
    (tmp_path / "broker").mkdir()
    mosquitto = Mosquitto(tmp_path / "broker", users={"bridge": SECRET})
    mosquitto.start()
    try:
        yield mosquitto
    finally:
        mosquitto.stop()


def password_file(tmp_path: Path, text: str = SECRET + "\n", mode: int = 0o600) -> Path:
    path = tmp_path / "mqtt-password"
    path.write_text(text)
    path.chmod(mode)
    return path


def bridge(port: int, *extra: str) -> list[str]:
    return ["--debug", "bridge", "-i", "virtual", "-c", f"secrets-{os.getpid()}",
            "--duration", "1", "--broker", f"mqtt://bridge@{LOOPBACK}:{port}", *extra]


def fleet(port: int, report: Path, *extra: str) -> list[str]:
    return ["--debug", "fleet", "-n", "2", "--duration", "1", "--max-miss-ratio", "1",
            "--report", str(report), "--broker", f"mqtt://bridge@{LOOPBACK}:{port}", *extra]


def artefacts(capsys: pytest.CaptureFixture[str], *roots: Path) -> str:
    """stdout, stderr and the text of every file under ``roots`` (reports, logs)."""
    out, err = capsys.readouterr()
    files = [p for root in roots for p in root.rglob("*") if p.is_file()]
    return "\n".join([out, err, *(p.read_text(errors="replace") for p in files)])


def only_late(report: dict[str, object]) -> bool:
    """Whether a fleet report fails only by real time: the loop fell behind on a loaded machine
    (deadline misses, releases skipped, so robots unjudged), never a pose out of tolerance.
    Exit 1 then says nothing of the password, what these tests check (they ran ``--duration
    1`` with ``--max-miss-ratio 1`` and still failed under load: 10-13 releases skipped)."""
    robots = report["per_robot"]
    assert isinstance(robots, dict)
    return all(r["verdict"] == "PASS" or (r["verdict"] == "UNJUDGED" and "releases skipped (the "
                                           "loop fell behind)" in r["reason"])
               for r in robots.values())


def clean_run_dir(tmp_path: Path) -> Path:
    """A directory for what the run writes (not the broker's files, which hold the hash)."""
    run = tmp_path / "run"
    run.mkdir(exist_ok=True)
    return run


@pytest.mark.parametrize("source", ["file", "env", "url"])
@pytest.mark.parametrize("command", ["bridge", "fleet"])
def test_the_password_never_shows_in_any_artefact(
    source: str, command: str, broker: Mosquitto, tmp_path: Path,
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:
    run = clean_run_dir(tmp_path)
    report = run / "report.json"
    argv = bridge(broker.port) if command == "bridge" else fleet(broker.port, report)
    if source == "file":
        argv += ["--password-file", str(password_file(tmp_path))]
    elif source == "env":
        monkeypatch.setenv(PASSWORD_ENV, SECRET)
    else:
        url = argv.index("--broker") + 1
        argv[url] = argv[url].replace("bridge@", f"bridge:{SECRET}@")
    code = main(argv)
    text = artefacts(capsys, run)
    if command == "fleet" and code == 1:  # a loaded machine: the fleet ran, late (not our check)
        assert only_late(json.loads(report.read_text())), text
    else:
        assert code == 0, text
    assert "DEBUG: Sending CONNECT" in text  # --debug: paho's own log lines are in there too
    assert SECRET not in text
    warnings = [line for line in text.splitlines() if "visible to other users" in line]
    assert len(warnings) == (1 if source == "url" else 0), text
    if command == "fleet":
        assert json.loads(report.read_text())["broker"] == f"mqtt://bridge@127.0.0.1:{broker.port}"


@pytest.mark.parametrize("command", ["bridge", "fleet"])
def test_a_refused_password_never_shows_either(
    command: str, broker: Mosquitto, tmp_path: Path, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The broker refuses ``SECRET`` + "x": the one error line (and --debug's traceback) name
    the user and the reason, never the password."""
    run = clean_run_dir(tmp_path)
    monkeypatch.setenv(PASSWORD_ENV, SECRET + "x")
    argv = bridge(broker.port) if command == "bridge" else fleet(broker.port, run / "r.json")
    code = main(argv[1:])  # without --debug: one line
    text = artefacts(capsys, run)
    assert code == 2
    assert f"error: cannot connect to mqtt://bridge@127.0.0.1:{broker.port}: not authorized" in text
    assert SECRET not in text
    assert main(argv) == 2  # --debug: the exception's traceback too, the same exit code
    trace = artefacts(capsys, run)
    assert "Traceback (most recent call last)" in trace
    assert "BrokerError" in trace
    assert "not authorized" in trace
    assert SECRET not in trace


def test_the_password_is_not_in_a_repr_or_str() -> None:
    url = BrokerURL.parse(f"mqtt://bridge:{SECRET}@127.0.0.1:1883")
    assert url.password == SECRET
    assert SECRET not in repr(url)
    assert SECRET not in str(url)
    assert SECRET not in repr(url.with_credentials("bridge", SECRET))


def test_a_readable_password_file_warns_and_still_works(
    broker: Mosquitto, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = password_file(tmp_path, mode=0o644)
    code = main(bridge(broker.port, "--password-file", str(path))[1:])  # without --debug
    _, err = capsys.readouterr()
    assert code == 0, err
    assert [line for line in err.splitlines() if line.startswith("warning:")] == [
        f"warning: --password-file {path} may be read by other users (mode 644): chmod 600 {path}"
    ]


@pytest.mark.parametrize(("case", "expected"), [
    ("missing", "--password-file {path}: cannot read it (No such file or directory)"),
    ("directory", "--password-file {path}: cannot read it (Is a directory)"),
    ("empty", "--password-file {path}: empty first line"),
    ("binary", "--password-file {path}: cannot read it (not UTF-8 text)"),
    ("and url", "--broker carries a password and --password-file gives one: give only one"),
    ("no user", "--password-file: a password needs a user name in --broker (mqtt://USER@host)"),
])
def test_a_bad_password_file_is_exit_2_and_one_line(
    case: str, expected: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Checked before any connection (port 1: nothing listens there)."""
    path = tmp_path / "pw"
    url = "mqtt://bridge@127.0.0.1:1"
    if case == "directory":
        path.mkdir()
    elif case == "empty":
        path.write_text("\n")
    elif case == "binary":
        path.write_bytes(b"\xff\xfe\x00")
    elif case != "missing":
        password_file(tmp_path)
        path = tmp_path / "mqtt-password"
        url = {"and url": f"mqtt://bridge:{SECRET}@127.0.0.1:1", "no user": "mqtt://127.0.0.1:1"}[case]
    argv = ["bridge", "-i", "virtual", "-c", "secrets-bad", "--broker", url,
            "--password-file", str(path)]
    code = main(argv)
    _, err = capsys.readouterr()
    assert code == 2
    assert err.splitlines() == [f"error: {expected.format(path=path)}"]


def test_the_monitor_takes_the_password_from_the_environment(
    broker: Mosquitto, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A wrong password in the environment is a refusal (so the variable is read), one line.
    The watch ends at the refusal, its --duration a bound (a 2 s watch that a loaded machine
    spent before the CONNACK said "cannot reach", not the refusal)."""
    monkeypatch.setenv(PASSWORD_ENV, "wrong")
    end_watch_once(monkeypatch, lambda watch: watch.connected_once)
    code = main(["monitor", "--json", "--duration", BOUND_S,
                 "--broker", f"mqtt://bridge@{LOOPBACK}:{broker.port}"])
    _, err = capsys.readouterr()
    assert code == 2
    assert err.splitlines() == [f"error: cannot connect to mqtt://bridge@127.0.0.1:{broker.port}: "
                                "not authorized (Not authorized)"]
