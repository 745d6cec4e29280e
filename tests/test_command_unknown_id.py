"""An unknown command's answer carries its id (trial13).

From outside, on a real bridge: ``{"id": "a10"}`` published on ``cmd/bogus`` was answered
``{"id": null, "command": "bogus", "result": "rejected", "reason": "unknown command 'bogus'
..."}``: the operator cannot tell which of its commands was refused (a typo in a topic, a
command a newer bridge knows). The encoder looked the command up before it read the id.
"""

from __future__ import annotations

import json

import pytest

from odocan.host.protocol.commands import CommandEncoder, CommandRejected


@pytest.mark.parametrize("cmd_id", ["a10", 7])
def test_an_unknown_command_is_rejected_with_its_id(cmd_id: object) -> None:
    with pytest.raises(CommandRejected) as caught:
        CommandEncoder().encode("bogus", json.dumps({"id": cmd_id, "x_m": 1.0}).encode())
    assert caught.value.cmd_id == cmd_id
    assert caught.value.reason.startswith("unknown command 'bogus'")


def test_an_unknown_command_without_a_valid_id_has_none() -> None:
    for payload in (b'{"x_m": 1.0}', b"not json", b'{"id": [1]}'):
        with pytest.raises(CommandRejected) as caught:
            CommandEncoder().encode("bogus", payload)
        assert caught.value.cmd_id is None
