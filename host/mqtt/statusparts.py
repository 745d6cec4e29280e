"""Small parts of the bridge's telemetry (``host.mqtt.telemetry``) kept out of its class: the
``rejected`` key of a foreign CAN ID, and the ``status`` sections said only when they say
something (``reference_adopted``, ``names_ahead``)."""

from __future__ import annotations

from typing import Any

from odocan.host.judge.liveadopted import AdoptedStarts
from odocan.host.judge.liveahead import LiveAhead


def unknown_key(seen: set[str], can_id: int, most: int) -> str:
    """``0x...`` for the first ``most`` foreign IDs (``seen``: those named so far), then
    ``other``: a bus of random IDs must not grow ``rejected`` (and the ``rates`` payload)
    without bound."""
    key = hex(can_id)
    if key in seen or len(seen) < most:
        seen.add(key)
        return key
    return "other"


def adopted_sections(adopted_starts: AdoptedStarts, ahead: LiveAhead) -> dict[str, Any]:
    """``reference_adopted`` while the reference starts at the firmware's pose (liveadopted),
    ``names_ahead`` once a pose named a frame not yet sent (``liveahead``); else nothing."""
    adopted, named_ahead = adopted_starts.as_dict(), ahead.as_dict()
    return {**({"reference_adopted": adopted} if adopted else {}),
            **({"names_ahead": named_ahead} if named_ahead else {})}
