"""``odocan monitor --broker``: no single telemetry message stops the fleet view (rule 6).

Found from outside with a real mosquitto: one pose of 50 000 nested ``[`` (a valid-looking
JSON document of 100 kB) ended ``monitor --broker --json`` with an exception-group traceback
(RecursionError from ``json.loads``, which ``fleetview.apply`` did not catch).
"""

from __future__ import annotations

import pytest

from odocan.host.mqtt.fleetview import MAX_TELEMETRY_BYTES, RobotState, apply

GOOD_POSE = b'{"x_m": 1.0, "y_m": 2.0, "heading_rad": 0.5}'


@pytest.mark.parametrize(
    "payload",
    [
        b"[" * 50_000 + b"]" * 50_000,  # RecursionError
        b"[" * 3_000 + b"]" * 3_000,  # deep, and within the size bound: RecursionError too
        b'{"x_m": ' + b"1" * 5_000 + b"}",  # int beyond sys.get_int_max_str_digits: ValueError
        b"{" * 10 + b" " * (MAX_TELEMETRY_BYTES + 1),  # over the bound: not even parsed
        b"\xff\xfe\x00",
    ],
)
def test_a_hostile_telemetry_payload_is_skipped_and_the_next_one_taken(payload: bytes) -> None:
    table: dict[str, RobotState] = {}
    assert apply(table, "odocan/robot001/pose", payload) is False
    assert apply(table, "odocan/robot001/pose", GOOD_POSE) is True
    assert table["robot001"].pose["x_m"] == 1.0


def test_the_bound_leaves_room_for_real_telemetry() -> None:
    """A rates payload of every DBC message and a status are well under 64 kB."""
    assert MAX_TELEMETRY_BYTES >= 64 * 1024
