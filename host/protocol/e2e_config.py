"""The E2E configuration of each DBC message (``host.protocol.e2e``'s receiver reads it), built
once per distinct message description.

``e2e_messages`` runs at every ``check_frames`` (a live hold reads its evidence every 40 ms of bus
time, ``host.judge.liveearly``) and in many judges; parsing each message's ``E2EDataIDs`` list
again each time was 2 % of the test suite. The configuration depends only on a message's name,
identifier, frame format, DLC, cycle time, send type and the two attributes' values: those
plain values (ints, floats, strings, compared with their types; an attribute not set is ``()``,
one set ``(value,)``) are the key of a bounded
cache (``_config``), so a DBC edited or another DBC gives its own entry, never a stale one.
A DBC whose list is malformed raises ``E2EConfigError`` every time (an exception is not cached).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING, Any

from odocan.host.protocol.busfacts import ENC_COUNTER_LAP, ENC_COUNTER_MASK
from odocan.host.protocol.decode import frame_key
from odocan.host.protocol.e2e_crc import P02_LENGTH
from odocan.sim.exceptions import OdocanError

if TYPE_CHECKING:  # a cantools Database or a plan of it (host.protocol.dbcplan)
    from odocan.host.protocol.dbcplan import DatabaseSpec, MessageSpec

COUNTER_LAP = ENC_COUNTER_LAP  # 16: every E2E COUNTER's values (the DBC's, one lap)
MAX_DELTA_COUNTER = ENC_COUNTER_MASK  # 15: the widest window, a lap less one
# Messages the firmware checks with MaxDeltaCounterInit 0 and a window widened once per period
# (firmware/encoders.py ``EncoderInput.rx``): only +1 passes without time having passed.
PER_PERIOD_WINDOW = frozenset({"WHEEL_ENCODERS"})
# distinct message descriptions kept (a DBC has tens; tests load a few edited DBCs)
CONFIG_CACHE = 1024
Attribute = tuple[()] | tuple[Any]  # a DBC attribute's value, (): not set


class E2EConfigError(OdocanError):
    """The DBC's E2E attributes cannot be used (a list that is not 16 data IDs of 0..255)."""


@dataclass(frozen=True)
class E2EMessage:
    """What the receiver needs of one message of the DBC."""

    name: str
    key: int  # decode.frame_key: identifier and frame format
    length: int  # DLC, bytes
    data_ids: tuple[int, ...] | None  # E2EDataIDs (16), None: not protected
    max_delta_init: int  # MaxDeltaCounterInit
    cycle_s: float | None  # receive period: GenMsgCycleTime / E2EFramesPerCycle (None: none)
    min_periods: int = 1  # periods a frame adds at least (0: the window widens with time only)


def e2e_messages(db: DatabaseSpec) -> dict[int, E2EMessage]:
    """The DBC's messages by ``frame_key``, with their E2E configuration (a new dict each call;
    its ``E2EMessage`` values, frozen, may be shared)."""
    return {m.key: m for m in (_e2e_message(message) for message in db.messages)}


def _e2e_message(message: MessageSpec) -> E2EMessage:
    attributes = message.dbc.attributes if message.dbc is not None else {}
    ids = (attributes["E2EDataIDs"].value,) if "E2EDataIDs" in attributes else ()
    frames = (attributes["E2EFramesPerCycle"].value,) if "E2EFramesPerCycle" in attributes else ()
    return _config(message.name, message.frame_id, message.is_extended_frame, message.length,
                   message.cycle_time, message.send_type, ids, frames)


@lru_cache(maxsize=CONFIG_CACHE, typed=True)
def _config(name: str, frame_id: int, extended: bool, length: int, cycle_time: int | None,
            send_type: str | None, ids: Attribute, frames: Attribute) -> E2EMessage:
    """One message's configuration from its plain DBC values (the module docstring)."""
    data_ids = None
    if ids:
        data_ids = _parse_data_ids(name, str(ids[0]))
        if length != P02_LENGTH:
            raise E2EConfigError(f"{name}: E2E Profile 2 needs 8-byte frames")
    cyclic = bool(cycle_time) and send_type in (None, "Cyclic")
    per_period = name in PER_PERIOD_WINDOW
    per_cycle = int(frames[0]) if frames else 1
    return E2EMessage(
        name=name,
        key=frame_key(frame_id, extended),
        length=length,
        data_ids=data_ids,
        max_delta_init=0 if per_period else 1 if cyclic else MAX_DELTA_COUNTER,
        cycle_s=cycle_time / 1000.0 / max(per_cycle, 1) if cycle_time else None,
        min_periods=0 if per_period else 1,
    )


def _parse_data_ids(name: str, text: str) -> tuple[int, ...]:
    try:
        ids = tuple(int(v) for v in text.split(","))
    except ValueError:
        raise E2EConfigError(f"{name}: E2EDataIDs {text!r} is not a list of integers") from None
    if len(ids) != COUNTER_LAP or not all(0 <= v <= 255 for v in ids):
        raise E2EConfigError(
            f"{name}: E2EDataIDs must list {COUNTER_LAP} data IDs of 0..255, got {text!r}")
    return ids
