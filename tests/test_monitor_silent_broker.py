"""``monitor --broker`` at a port that accepts TCP and never answers MQTT (trial13).

From outside: a listener that accepts and says nothing (a wrong port, a hung broker) made
``odocan monitor --broker mqtt://127.0.0.1:PORT --duration 2 --json`` end with
``error: cannot reach the MQTT broker mqtt://127.0.0.1:PORT: `` and nothing after the colon:
the connection attempt was still waiting when the duration ended, so no error was recorded.
"""

from __future__ import annotations

import socket

import pytest

from odocan.host.cli.app import main
from tests.test_cli_run import assert_usage_error


def test_a_silent_listener_is_named_as_no_mqtt_answer(capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen()
        url = f"mqtt://127.0.0.1:{listener.getsockname()[1]}"
        code = main(["monitor", "--broker", url, "--duration", "0.5", "--json"])
    line = assert_usage_error(capsys, code, "cannot reach the MQTT broker", url)
    assert "no MQTT answer in" in line, line
