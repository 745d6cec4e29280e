"""The facts the judges read of a DBC, as one value (``JudgeFacts``), and the check that a DBC a
command names (``--dbc``) gives the judges of this process the same facts.

``busfacts`` reads these facts once, at import, of the DBC at ``sim.contract.DBC_PATH``
(``ODOCAN_DBC``) and the judges hold them as module constants (the per-frame paths read a global).
So one process judges with one DBC's facts: ``odocan analyze --dbc OTHER`` and ``monitor --dbc
OTHER`` make OTHER that DBC when they start (``host.cli.dbcfirst``); where the judges were loaded
already (a second command in one interpreter, a batch worker), ``require_judges_follow`` refuses
a DBC whose facts differ, naming the first such fact -- never a verdict with one DBC's frames and
another's cycle times.

A message the named DBC does not define is not compared: no frame is decoded as it (the
command's own checks refuse a DBC that lacks a message it needs). A message it defines without a
fact the judges read (a cycle time, a COUNTER, a ``VAL_`` entry) is refused (``DbcFactError``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, NamedTuple

from odocan.sim.exceptions import OdocanError

if TYPE_CHECKING:
    from odocan.host.protocol.dbcplan import DatabaseSpec, SignalSpec

MS_PER_S = 1000
ENC_MESSAGE, POSE_MESSAGE, STATUS_MESSAGE = "WHEEL_ENCODERS", "ODOM_POSE_X", "ODOM_STATUS"
FRESHNESS_MESSAGE = "ODOM_FRESHNESS"
# AUTOSAR E2E Profile 2's COUNTER is 4 bits (its DataIDList has 16 entries): not the DBC's fact
# but the profile's, the most a DBC's COUNTER may count for the Profile 2 checks (``e2e``)
PROFILE2_MAX_COUNTER_LAP = 16


class DbcFactError(OdocanError):
    """The DBC lacks a fact the judges read of it (a cycle time, a COUNTER, a VAL_ entry), or
    gives one other than the DBC the judges of this process were loaded with."""


def _signal(plan: DatabaseSpec, name: str, signal: str) -> SignalSpec:
    try:
        return plan.get_message_by_name(name).get_signal_by_name(signal)
    except KeyError:
        raise DbcFactError(f"the DBC has no message {name} with a signal {signal}") from None


def cycle_ms(plan: DatabaseSpec, name: str) -> int:
    """Message ``name``'s ``GenMsgCycleTime`` (ms)."""
    try:
        cycle = plan.get_message_by_name(name).cycle_time
    except KeyError:
        raise DbcFactError(f"the DBC has no message {name}") from None
    if not cycle:
        raise DbcFactError(f"{name} has no GenMsgCycleTime in the DBC")
    return int(cycle)


def frames_per_cycle(plan: DatabaseSpec, name: str) -> int:
    """Message ``name``'s ``E2EFramesPerCycle`` (1 when the DBC gives none: its default)."""
    dbc = plan.get_message_by_name(name).dbc
    attributes = {} if dbc is None else dbc.attributes
    frames = attributes.get("E2EFramesPerCycle")
    return 1 if frames is None else int(frames.value)


def counter_lap(plan: DatabaseSpec, name: str, signal: str = "COUNTER") -> int:
    """The values of message ``name``'s ``signal`` (a COUNTER of n bits: 2 ** n)."""
    return 1 << _signal(plan, name, signal).length


def e2e_counter_lap(plan: DatabaseSpec) -> int:
    """The one lap of every E2E COUNTER of ``plan`` (a signal ``COUNTER`` or ``*_COUNTER``,
    which echoes one: 2 ** its bits), WHEEL_ENCODERS' first. A COUNTER past Profile 2's 16
    values is refused first, itself named (not a message whose COUNTER differs from it); then,
    as the E2E checks (``e2e``, ``e2e_live``, ``e2e_evidence``, ``e2e_held``, ``e2e_retract``,
    the placements) read one lap for every message, a DBC whose COUNTERs differ is refused,
    the first such signal named."""
    counters = [(message.name, signal.name, 1 << signal.length)
                for message in plan.messages for signal in message.signals
                if signal.name == "COUNTER" or signal.name.endswith("_COUNTER")]
    for name, signal_name, its in counters:
        if its > PROFILE2_MAX_COUNTER_LAP:
            raise DbcFactError(f"{name} {signal_name} values {its}: E2E Profile 2 counts at"
                               f" most {PROFILE2_MAX_COUNTER_LAP}")
    lap = counter_lap(plan, ENC_MESSAGE)
    for name, signal_name, its in counters:
        if its != lap:
            raise DbcFactError(
                f"{name} {signal_name} values {its} vs {ENC_MESSAGE} COUNTER's {lap}: the"
                " judges' E2E checks read one COUNTER lap for every message")
    return lap


def signal_bits(plan: DatabaseSpec, name: str, signal: str) -> int:
    """The length in bits of message ``name``'s ``signal``."""
    return int(_signal(plan, name, signal).length)


def choice(plan: DatabaseSpec, name: str, signal: str, value_name: str) -> int:
    """The raw value the DBC's ``VAL_`` table of ``name``'s ``signal`` names ``value_name``."""
    choices = _signal(plan, name, signal).choices or {}
    for raw, named in choices.items():
        if named == value_name:
            return int(raw)
    raise DbcFactError(f"{name} {signal} has no value {value_name} in the DBC")


def lsb_ms(plan: DatabaseSpec, name: str, signal: str) -> int:
    """The scale of a signal in seconds, as whole ms per LSB."""
    return round(_signal(plan, name, signal).scale * MS_PER_S)


Reader = Callable[["DatabaseSpec"], int]
# (JudgeFacts field, the message it is of, what it is in the DBC, how it is read): the one list
READERS: tuple[tuple[str, str, str, Reader], ...] = (
    ("enc_cycle_ms", ENC_MESSAGE, "GenMsgCycleTime (ms)", lambda p: cycle_ms(p, ENC_MESSAGE)),
    ("enc_counter_lap", ENC_MESSAGE, "COUNTER values", e2e_counter_lap),
    ("enc_wire_counter_bits", ENC_MESSAGE, "LEFT_COUNT bits",
     lambda p: signal_bits(p, ENC_MESSAGE, "LEFT_COUNT")),
    ("pose_cycle_ms", POSE_MESSAGE, "GenMsgCycleTime (ms)", lambda p: cycle_ms(p, POSE_MESSAGE)),
    ("pose_frames_per_cycle", POSE_MESSAGE, "E2EFramesPerCycle",
     lambda p: frames_per_cycle(p, POSE_MESSAGE)),
    ("pose_counter_lap", POSE_MESSAGE, "COUNTER values", lambda p: counter_lap(p, POSE_MESSAGE)),
    ("pose_enc_counter_lap", POSE_MESSAGE, "ENC_COUNTER values",
     lambda p: counter_lap(p, POSE_MESSAGE, "ENC_COUNTER")),
    ("status_cycle_ms", STATUS_MESSAGE, "GenMsgCycleTime (ms)",
     lambda p: cycle_ms(p, STATUS_MESSAGE)),
    ("status_frames_per_cycle", STATUS_MESSAGE, "E2EFramesPerCycle",
     lambda p: frames_per_cycle(p, STATUS_MESSAGE)),
    ("status_counter_lap", STATUS_MESSAGE, "COUNTER values",
     lambda p: counter_lap(p, STATUS_MESSAGE)),
    ("freshness_cycle_ms", FRESHNESS_MESSAGE, "GenMsgCycleTime (ms)",
     lambda p: cycle_ms(p, FRESHNESS_MESSAGE)),
    ("uptime_lsb_ms", STATUS_MESSAGE, "UPTIME scale (ms)",
     lambda p: lsb_ms(p, STATUS_MESSAGE, "UPTIME")),
    ("summary_page", STATUS_MESSAGE, "PAGE SUMMARY",
     lambda p: choice(p, STATUS_MESSAGE, "PAGE", "SUMMARY")),
    ("totals_page", STATUS_MESSAGE, "PAGE FRAME_TOTALS",
     lambda p: choice(p, STATUS_MESSAGE, "PAGE", "FRAME_TOTALS")),
    ("enc_e2e_page", STATUS_MESSAGE, "PAGE E2E_WHEEL_ENCODERS",
     lambda p: choice(p, STATUS_MESSAGE, "PAGE", "E2E_WHEEL_ENCODERS")),
    ("profile_page", STATUS_MESSAGE, "PAGE PROFILE",
     lambda p: choice(p, STATUS_MESSAGE, "PAGE", "PROFILE")),
    ("apply_field", "ODOM_SET_POSE", "FIELD APPLY",
     lambda p: choice(p, "ODOM_SET_POSE", "FIELD", "APPLY")),
    ("apply_param", "ODOM_CONFIG", "PARAM APPLY",
     lambda p: choice(p, "ODOM_CONFIG", "PARAM", "APPLY")),
)


class JudgeFacts(NamedTuple):
    """Every fact the judges read of one DBC (``busfacts`` holds them as constants; the values
    of dbc/odocan.dbc in the comments). A NamedTuple, not a dataclass: built at every start-up,
    and a dataclass compiles its methods then (8.7M instructions, callgrind)."""

    enc_cycle_ms: int  # 10
    enc_counter_lap: int  # 16: a 4-bit E2E COUNTER
    enc_wire_counter_bits: int  # 24
    pose_cycle_ms: int  # 20
    pose_frames_per_cycle: int  # 1
    pose_counter_lap: int  # 16
    pose_enc_counter_lap: int  # 16
    status_cycle_ms: int  # 100
    status_frames_per_cycle: int  # 2: the summary and a page
    status_counter_lap: int  # 16
    freshness_cycle_ms: int  # 1000
    uptime_lsb_ms: int  # 1000
    summary_page: int  # 0
    totals_page: int  # 1
    enc_e2e_page: int  # 2
    profile_page: int  # 6
    apply_field: int  # 15
    apply_param: int  # 15


def judge_facts(plan: DatabaseSpec) -> JudgeFacts:
    """The facts of ``plan`` (a ``DbcPlan`` or a cantools ``Database``); ``DbcFactError`` names
    the first one it lacks."""
    return JudgeFacts(**{name: read(plan) for name, _, _, read in READERS})


def cycles_ms(plan: DatabaseSpec) -> dict[str, int]:
    """Every cyclic message's ``GenMsgCycleTime`` (ms) by name (``sim.contract.cycle_time_s``
    reads them of the process's DBC)."""
    return {m.name: int(m.cycle_time) for m in plan.messages if m.cycle_time}


def first_difference(named: DatabaseSpec, loaded: DatabaseSpec) -> str | None:
    """The first fact the judges read that ``named`` gives otherwise than ``loaded`` (the DBC
    this process's judges were loaded with), said as ``what: named's vs loaded's``; None when
    they agree. A message ``named`` does not define is not compared; one it defines without a
    fact is ``DbcFactError``."""
    names = {m.name for m in named.messages}
    ours, theirs = cycles_ms(loaded), cycles_ms(named)
    for name, cycle in ours.items():
        if name in names and theirs.get(name) != cycle:
            return f"{name} GenMsgCycleTime (ms) {theirs.get(name)} vs {cycle}"
    for _, message, what, read in READERS:
        if message in names and (its := read(named)) != (mine := read(loaded)):
            return f"{message} {what} {its} vs {mine}"
    return None


def missing_signals(named: DatabaseSpec, shipped: DatabaseSpec) -> str | None:
    """The first message ``named`` defines without every signal ``shipped`` (odocan's own DBC)
    gives it, said as ``MESSAGE lacks SIGNAL, ...``; None when none lacks one. The judges read
    the signals by name: a lacking one was a ``KeyError`` deep in a judge (an outside trial: a
    DBC without ODOM_POSE_Y's TURNS, exit 1 and a traceback, read by CI as a FAIL)."""
    names = {m.name: m for m in named.messages}
    for message in shipped.messages:
        if message.name not in names:
            continue  # the command refuses a DBC lacking a message it needs
        have = {signal.name for signal in names[message.name].signals}
        lacking = [signal.name for signal in message.signals if signal.name not in have]
        if lacking:
            return f"{message.name} lacks {', '.join(lacking)}"
    return None
