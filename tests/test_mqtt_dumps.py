"""MQTT payload JSON: encoded as it is, yet byte for byte what the NaN-safe copy encodes."""

from __future__ import annotations

import json
from typing import Any

from hypothesis import given
from hypothesis import strategies as st

from odocan.host.jsonutil import finite
from odocan.host.mqtt.topics import dumps

LEAVES = st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=5)
PAYLOADS = st.dictionaries(
    st.text(max_size=5),
    st.recursive(LEAVES, lambda inner: st.lists(inner, max_size=3)
                 | st.dictionaries(st.text(max_size=5), inner, max_size=3), max_leaves=12),
    max_size=6,
)


@given(PAYLOADS)
def test_dumps_is_the_finite_copy_encoded(payload: dict[str, Any]) -> None:
    assert dumps(payload) == json.dumps(finite(payload), separators=(",", ":")).encode()


def test_non_finite_floats_become_null_wherever_they_are() -> None:
    payload = {"x": float("nan"), "a": [1.0, float("inf"), {"b": float("-inf")}], "ok": 0.5}
    assert json.loads(dumps(payload)) == {"x": None, "a": [1.0, None, {"b": None}], "ok": 0.5}
