"""The bus facts the judges build on, read of the DBC once at import (rule: the DBC is the single
source of truth for frames).

Cycle times (``GenMsgCycleTime``, ms), frames per cycle (``E2EFramesPerCycle``), E2E COUNTER
laps (2 ** the COUNTER signal's length), the ODOM_STATUS page numbers and the APPLY codes (the
``VAL_`` tables), UPTIME's LSB and the encoder counts' wire width: each judge once restated them
as its own literal. Here they are read of the DBC at ``sim.contract.DBC_PATH`` (``ODOCAN_DBC``)
through the judge's plan of it (``dbcplan.default_plan``: no cantools on a warm cache), so a
DBC edited there is followed. Plain module constants: the per-frame paths read a global, as they
read the literals before. A DBC that lacks one of them is refused at import (``DbcFactError``),
never patched with a default.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from odocan.host.protocol.dbcplan import default_plan
from odocan.sim.exceptions import OdocanError

if TYPE_CHECKING:
    from odocan.host.protocol.dbcplan import DbcPlan, PlanSignal

MS_PER_S = 1000


class DbcFactError(OdocanError):
    """The DBC lacks a fact the judges read of it (a cycle time, a COUNTER, a VAL_ entry)."""


def _signal(plan: DbcPlan, name: str, signal: str) -> PlanSignal:
    try:
        return plan.get_message_by_name(name).get_signal_by_name(signal)
    except KeyError:
        raise DbcFactError(f"the DBC has no message {name} with a signal {signal}") from None


def cycle_ms(plan: DbcPlan, name: str) -> int:
    """Message ``name``'s ``GenMsgCycleTime`` (ms)."""
    try:
        cycle = plan.get_message_by_name(name).cycle_time
    except KeyError:
        raise DbcFactError(f"the DBC has no message {name}") from None
    if not cycle:
        raise DbcFactError(f"{name} has no GenMsgCycleTime in the DBC")
    return int(cycle)


def frames_per_cycle(plan: DbcPlan, name: str) -> int:
    """Message ``name``'s ``E2EFramesPerCycle`` (1 when the DBC gives none: its default)."""
    dbc = plan.get_message_by_name(name).dbc
    attributes = {} if dbc is None else dbc.attributes
    frames = attributes.get("E2EFramesPerCycle")
    return 1 if frames is None else int(frames.value)


def counter_lap(plan: DbcPlan, name: str, signal: str = "COUNTER") -> int:
    """The values of message ``name``'s ``signal`` (a COUNTER of n bits: 2 ** n)."""
    return 1 << _signal(plan, name, signal).length


def signal_bits(plan: DbcPlan, name: str, signal: str) -> int:
    """The length in bits of message ``name``'s ``signal``."""
    return _signal(plan, name, signal).length


def choice(plan: DbcPlan, name: str, signal: str, value_name: str) -> int:
    """The raw value the DBC's ``VAL_`` table of ``name``'s ``signal`` names ``value_name``."""
    choices = _signal(plan, name, signal).choices or {}
    for raw, named in choices.items():
        if named == value_name:
            return raw
    raise DbcFactError(f"{name} {signal} has no value {value_name} in the DBC")


def lsb_ms(plan: DbcPlan, name: str, signal: str) -> int:
    """The scale of a signal in seconds, as whole ms per LSB."""
    return round(_signal(plan, name, signal).scale * MS_PER_S)


_PLAN = default_plan()

ENC_MESSAGE, POSE_MESSAGE, STATUS_MESSAGE = "WHEEL_ENCODERS", "ODOM_POSE_X", "ODOM_STATUS"
ENC_CYCLE_MS = cycle_ms(_PLAN, ENC_MESSAGE)  # 10
ENC_CYCLE_S = ENC_CYCLE_MS / MS_PER_S
ENC_COUNTER_LAP = counter_lap(_PLAN, ENC_MESSAGE)  # 16: a 4-bit E2E COUNTER
ENC_WIRE_COUNTER_BITS = signal_bits(_PLAN, ENC_MESSAGE, "LEFT_COUNT")  # 24
POSE_CYCLE_MS = cycle_ms(_PLAN, POSE_MESSAGE)  # 20
POSE_FRAMES_PER_CYCLE = frames_per_cycle(_PLAN, POSE_MESSAGE)  # 1
POSE_COUNTER_LAP = counter_lap(_PLAN, POSE_MESSAGE)  # 16
STATUS_CYCLE_MS = cycle_ms(_PLAN, STATUS_MESSAGE)  # 100
STATUS_FRAMES_PER_CYCLE = frames_per_cycle(_PLAN, STATUS_MESSAGE)  # 2: the summary and a page
STATUS_COUNTER_LAP = counter_lap(_PLAN, STATUS_MESSAGE)  # 16
FRESHNESS_CYCLE_MS = cycle_ms(_PLAN, "ODOM_FRESHNESS")  # 1000
UPTIME_LSB_MS = lsb_ms(_PLAN, STATUS_MESSAGE, "UPTIME")  # 1000
SUMMARY_PAGE = choice(_PLAN, STATUS_MESSAGE, "PAGE", "SUMMARY")  # 0
TOTALS_PAGE = choice(_PLAN, STATUS_MESSAGE, "PAGE", "FRAME_TOTALS")  # 1
ENC_E2E_PAGE = choice(_PLAN, STATUS_MESSAGE, "PAGE", "E2E_WHEEL_ENCODERS")  # 2
PROFILE_PAGE = choice(_PLAN, STATUS_MESSAGE, "PAGE", "PROFILE")  # 6
APPLY_FIELD = choice(_PLAN, "ODOM_SET_POSE", "FIELD", "APPLY")  # 15
APPLY_PARAM = choice(_PLAN, "ODOM_CONFIG", "PARAM", "APPLY")  # 15
