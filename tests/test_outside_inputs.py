"""Bad input found from outside: each is one ``error: ...`` line and exit 2, never a traceback.

Every case here printed a traceback (exit 1) or was taken silently before its fix.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from odocan.host.cli.app import main
from odocan.host.mqtt.broker import BrokerURL
from odocan.sim.exceptions import ConfigurationError


def _one_error_line(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    code = main(argv)
    out, err = capsys.readouterr()
    assert code == 2, (out, err)
    assert err.count("\n") == 1 and err.startswith("error: "), err
    return err


@pytest.mark.parametrize(
    ("url", "why"),
    [
        ("mqtt://[::1", "Invalid IPv6 URL"),  # a traceback (ValueError from urlsplit)
        ("mqtt://[zz]:1883", "does not appear to be an IPv4 or IPv6 address"),
        ("mqtts://broker:0", "port 0"),  # was taken as the default 8883
        ("mqtt://broker:0", "port 0"),
    ],
)
def test_a_malformed_broker_url_is_refused_in_one_line(url: str, why: str) -> None:
    with pytest.raises(ConfigurationError, match=why):
        BrokerURL.parse(url)


@pytest.mark.parametrize("command", ["bridge", "fleet", "monitor"])
def test_every_mqtt_command_refuses_a_malformed_broker_url(
    command: str, capsys: pytest.CaptureFixture[str]
) -> None:
    err = _one_error_line(capsys, [command, "--broker", "mqtt://[::1"])
    assert "--broker 'mqtt://[::1'" in err
