"""A ``sent_unix_s`` in milliseconds is refused, not run as "age 0" forever (trial13).

From outside, on a real bridge: ``{"id": "a5", ..., "sent_unix_s": 1e300}`` was accepted and run,
as is a stamp in ms (JavaScript's ``Date.now()`` without the ``/ 1000`` the docs ask for): a
stamp ahead of the bridge's clock counts as age 0, so such a command never expires by its stamp,
however long it waited. A day or more ahead is refused with its reason; a few seconds ahead (a
clock a little off) still runs.
"""

from __future__ import annotations

import json
import time

import pytest

from odocan.host.protocol.commands import CommandEncoder, CommandRejected

POSE = {"x_m": 1.0, "y_m": 2.0, "heading_rad": 0.0}


def _encode(sent: float) -> object:
    payload = json.dumps({"id": "ms", **POSE, "sent_unix_s": sent}).encode()
    return CommandEncoder().encode("set_pose", payload)


# Named ids: xdist's workers collect at different times, and must collect the same tests.
@pytest.mark.parametrize("sent", [time.time() * 1000.0, 1e300, time.time() + 2 * 86_400.0],
                         ids=["milliseconds", "1e300", "two_days_ahead"])
def test_a_stamp_a_day_or_more_ahead_is_refused_with_its_reason(sent: float) -> None:
    with pytest.raises(CommandRejected) as caught:
        _encode(sent)
    assert caught.value.cmd_id == "ms"
    assert "not UNIX seconds" in caught.value.reason
    _encode(time.time() + 7.0)  # a clock a little ahead: run (the arrival rule bounds it)
