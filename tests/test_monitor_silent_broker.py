"""``monitor --broker`` at a port that accepts TCP and never answers MQTT (trial13).

From outside: a listener that accepts and says nothing (a wrong port, a hung broker) made
``odocan monitor --broker mqtt://127.0.0.1:PORT --duration 2 --json`` end with
``error: cannot reach the MQTT broker mqtt://127.0.0.1:PORT: `` and nothing after the colon:
the connection attempt was still waiting when the duration ended, so no error was recorded.
"""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from odocan.host.cli.app import main
from odocan.host.mqtt.broker import free_loopback_port
from tests.fleet_watch_until import BOUND_S, end_watch_once
from tests.requires import require_executables
from tests.test_cli_run import assert_usage_error


def test_a_silent_listener_is_named_as_no_mqtt_answer(capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen()
        url = f"mqtt://127.0.0.1:{listener.getsockname()[1]}"
        code = main(["monitor", "--broker", url, "--duration", "0.5", "--json"])
    line = assert_usage_error(capsys, code, "cannot reach the MQTT broker", url)
    assert "no MQTT answer in" in line, line


@pytest.fixture
def bare_mosquitto() -> Iterator[str]:
    """A mosquitto with no users, no robots: the URL of a broker that answers and is empty."""
    require_executables("mosquitto", install="apt-get install mosquitto")
    port = free_loopback_port()
    proc = subprocess.Popen(["mosquitto", "-p", str(port)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 10
        while True:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
                break
            except OSError:
                assert time.monotonic() < deadline, "mosquitto did not start"
                time.sleep(0.02)
        yield f"mqtt://127.0.0.1:{port}"
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def test_an_empty_broker_is_reached_not_unreachable(
    bare_mosquitto: str, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Before any robot publishes, the broker answered: the watch ends with no robots, exit 0
    (it said "cannot reach the MQTT broker ...: no MQTT answer in 1.0 s", exit 2: the table's
    first message was taken for the connection). The monitor ends once connected (its 1 s,
    connection included, is a loaded machine's stall)."""
    end_watch_once(monkeypatch, lambda watch: watch.connected_once)
    code = main(["monitor", "--broker", bare_mosquitto, "--duration", BOUND_S, "--json"])
    out, err = capsys.readouterr()
    assert (code, err) == (0, ""), err
    assert json.loads(out)["robots"] == {}


def test_the_last_screen_ends_its_line_off_a_terminal(bare_mosquitto: str, tmp_path: Path) -> None:
    """stdout to a file: the fleet table's last screen ends with a newline (an error line or the
    shell's prompt followed it on the same line). Its 4 s: the connection's bound (a process of
    its own, not patched to end once connected; 1 s was a loaded machine's stall)."""
    out = tmp_path / "screen.txt"
    with out.open("w") as stdout:
        done = subprocess.run([sys.executable, "-m", "odocan", "monitor", "--broker",
                               bare_mosquitto, "--duration", "4"], stdout=stdout,
                              stderr=subprocess.PIPE, text=True, timeout=60, check=False)
    assert done.returncode == 0, done.stderr
    screen = out.read_text()
    assert "robot" in screen, screen
    assert screen.endswith("\n"), repr(screen[-40:])
