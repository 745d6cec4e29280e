"""A JSON null for an optional command field is its absence (#13): ``"sent_unix_s": null`` was
refused as "must be a number", although most clients write an unset optional field as null. A
null for a required field is still refused."""

from __future__ import annotations

import json
from typing import Any

import pytest

from odocan.host.protocol.commands import Command, CommandEncoder, CommandRejected


def _encode(name: str, obj: dict[str, Any]) -> Command:
    return CommandEncoder().encode(name, json.dumps(obj).encode())  # fresh E2E counters


POSE = {"id": 7, "x_m": 1.0, "y_m": 2.0, "heading_rad": 0.5}
CONFIG = {"counts_per_rev": 4096, "wheel_radius_left_m": 0.1, "wheel_radius_right_m": 0.1,
          "wheelbase_m": 0.5, "counter_bits": 16, "integrator": "exact"}


@pytest.mark.parametrize(("name", "given", "optional"), [
    ("set_pose", POSE, "sent_unix_s"),
    ("config", CONFIG, "max_wheel_speed_m_s"),
    ("nav_goal", {"x_m": 1.0, "y_m": 2.0}, "heading_rad"),
    ("nav_goal", {"x_m": 1.0, "y_m": 2.0}, "goal_id"),
])
def test_a_null_optional_field_sends_what_its_absence_sends(
    name: str, given: dict[str, Any], optional: str
) -> None:
    with_null = _encode(name, {**given, optional: None})
    absent = _encode(name, given)
    assert with_null.frames == absent.frames
    assert with_null.cmd_id == absent.cmd_id


def test_a_null_required_field_is_still_refused() -> None:
    with pytest.raises(CommandRejected) as caught:
        _encode("set_pose", {**POSE, "x_m": None})
    assert caught.value.reason == "x_m must be a number"
