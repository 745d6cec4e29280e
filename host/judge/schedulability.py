"""Worst-case response times of CAN 2.0 frames by the revised analysis of Davis et al. (2007).

R. I. Davis, A. Burns, R. J. Bril, J. J. Lukkien, "Controller Area Network (CAN) schedulability
analysis: refuted, revisited and revised", Real-Time Systems 35(3):239-272, 2007. §2 gives the
model and the frame lengths, §3 Tindell's original analysis and the three-message set on which it
is optimistic, §4 the revised analysis implemented here. (The section numbers are cited from
memory of the paper, not checked against a copy; the formulas below do not rest on them: the tests
prove them against field widths, an exhaustive stuffing search and a simulation of arbitration.)

**The model (§2).** Fixed priorities: the lower identifier wins arbitration (a standard frame beats
an extended one with the same 11-bit base). A frame, once started, is not preempted. Every message
``m`` has a worst-case transmission time ``C_m`` (worst-case bit stuffing, interframe space
included), a period or minimum inter-arrival time ``T_m``, a deadline ``D_m`` and a queuing jitter
``J_m`` (how late after its nominal release it may be queued). Each node keeps its pending frames
in priority order and never aborts one (the analysis' own assumptions: no FIFO queues, no error
frames). Response times are measured from the nominal release: ``R_m`` includes ``J_m``.

**Frame length (§2).** A data frame with ``s`` data bytes has ``g + 8 s`` bits exposed to bit
stuffing (``g`` = 34 with an 11-bit ID, 54 with a 29-bit ID: SOF, arbitration and control fields,
CRC), 13 bits that are not (CRC delimiter, ACK slot and delimiter, 7 EOF, 3 interframe space) and
at most ``floor((g + 8 s - 1) / 4)`` stuff bits; for 11-bit IDs that is ``55 + 10 s`` bits.

**The revised analysis (§4)**, with ``hp(m)``/``lp(m)`` the messages of higher/lower priority and
``hep(m) = hp(m) + {m}``::

    B_m    = max_{k in lp(m)} C_k                                      blocking (0 for the lowest)
    t_m    = B_m + sum_{k in hep(m)} ceil((t_m + J_k) / T_k) C_k        level-m busy period
    Q_m    = ceil((t_m + J_m) / T_m)                                    instances of m in it
    w_m(q) = B_m + q C_m + sum_{k in hp(m)} ceil((w_m(q) + J_k + tau_bit) / T_k) C_k
    R_m(q) = J_m + w_m(q) - q T_m + C_m,   q = 0 .. Q_m - 1;   R_m = max_q R_m(q)

each recurrence solved as the least fixed point by iteration from below. Every time here is a whole
number of nanoseconds (each standard bitrate's bit time is), so the arithmetic is exact and a run
is the same on every machine.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from decimal import Decimal, InvalidOperation
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from cantools.database.can import Database, Message

from odocan.sim.exceptions import ConfigurationError

# The bitrates CAN controllers and CiA 102 / ISO 11898 networks use, in bit/s.
BITRATES = (10_000, 20_000, 50_000, 100_000, 125_000, 250_000, 500_000, 800_000, 1_000_000)
NS_PER_S = 1_000_000_000
NS_PER_MS = 1_000_000
STUFFED_BITS_STANDARD = 34  # g: SOF 1, ID 11, RTR 1, IDE 1, r0 1, DLC 4, CRC 15
STUFFED_BITS_EXTENDED = 54  # g: SOF 1, ID 11, SRR 1, IDE 1, ID 18, RTR 1, r1 1, r0 1, DLC 4, CRC 15
UNSTUFFED_BITS = 13  # CRC delimiter 1, ACK slot 1, ACK delimiter 1, EOF 7, interframe space 3
MAX_DLC = 8
MAX_FRAMES_PER_CYCLE = 16  # the DBC's E2EFramesPerCycle range (a 4-bit COUNTER's steps)
# A fixed point past this much bus time, or not reached in this many steps, is called unbounded
# and its message reported as one that can miss its deadline. Below 100 % utilization every busy
# period ends; at exactly 100 % one with blocking never does, and the analysis gives no bound.
HORIZON_NS = 60 * NS_PER_S
MAX_STEPS = 100_000


def bit_time_ns(bitrate: int) -> int:
    """One bit time in ns at ``bitrate`` bit/s; only the standard CAN bitrates are accepted."""
    if bitrate not in BITRATES:
        rates = ", ".join(f"{rate // 1000}k" for rate in BITRATES)
        raise ConfigurationError(f"{bitrate} bit/s is not a CAN bitrate (use one of {rates})")
    return NS_PER_S // bitrate


def frame_bits(dlc: int, *, extended: bool) -> int:
    """Worst-case length in bits of a CAN 2.0 data frame of ``dlc`` bytes (§2), IFS included."""
    if not 0 <= dlc <= MAX_DLC:
        raise ConfigurationError(f"DLC {dlc} is not a CAN 2.0 data length (0..8 bytes)")
    stuffed = (STUFFED_BITS_EXTENDED if extended else STUFFED_BITS_STANDARD) + 8 * dlc
    return stuffed + UNSTUFFED_BITS + (stuffed - 1) // 4


def arbitration_key(can_id: int, *, extended: bool) -> int:
    """An integer that orders frames as arbitration does: the smaller key wins the bus."""
    if extended:
        return ((can_id >> 18) << 19) | (1 << 18) | (can_id & 0x3FFFF)
    return can_id << 19


@dataclass(frozen=True)
class Flow:
    """One message stream as the analysis sees it; times in ns, ``priority`` smaller = higher."""

    name: str
    priority: int
    c_ns: int  # worst-case transmission time
    t_ns: int  # period, or minimum inter-arrival time
    d_ns: int  # deadline, measured from the nominal release
    j_ns: int = 0  # queuing jitter


@dataclass(frozen=True)
class Response:
    """The analysis of one flow: blocking, busy period, worst response (None if unbounded)."""

    flow: Flow
    b_ns: int
    busy_ns: int | None
    instances: int  # Q_m, instances of m in its busy period (0 when unbounded)
    r_ns: int | None
    worst_instance: int  # the q that gives R_m

    @property
    def slack_ns(self) -> int | None:
        """D_m - R_m (negative: the message can miss its deadline); None when unbounded."""
        return None if self.r_ns is None else self.flow.d_ns - self.r_ns

    @property
    def meets_deadline(self) -> bool:
        """True when R_m <= D_m."""
        return self.r_ns is not None and self.r_ns <= self.flow.d_ns


def _ceil_div(a: int, b: int) -> int:
    return -(-a // b)


def utilization(flows: list[Flow]) -> float:
    """Bus utilization: sum of C_k / T_k (1.0 = the bus never idles)."""
    return math.fsum(flow.c_ns / flow.t_ns for flow in flows)


def _interference_ns(window_ns: int, flows: list[Flow], tau_ns: int) -> int:
    """Transmission time of the ``flows`` queued before a window of ``window_ns`` (+ tau) ends."""
    return sum(_ceil_div(window_ns + k.j_ns + tau_ns, k.t_ns) * k.c_ns for k in flows)


def busy_period_ns(flow: Flow, hep: list[Flow], b_ns: int) -> int | None:
    """t_m: the longest priority level-m busy period (§4); None when unbounded (``HORIZON_NS``)."""
    t_ns = flow.c_ns
    for _ in range(MAX_STEPS):
        nxt = b_ns + _interference_ns(t_ns, hep, 0)
        if nxt == t_ns:
            return t_ns
        if nxt > HORIZON_NS:
            return None
        t_ns = nxt
    return None


def queuing_delay_ns(flow: Flow, hp: list[Flow], b_ns: int, q: int, tau_ns: int) -> int | None:
    """w_m(q): from the critical instant to the start of instance q of m (§4); None if unbounded."""
    w_ns = b_ns + q * flow.c_ns + sum(k.c_ns for k in hp)
    for _ in range(MAX_STEPS):
        nxt = b_ns + q * flow.c_ns + _interference_ns(w_ns, hp, tau_ns)
        if nxt == w_ns:
            return w_ns
        if nxt > HORIZON_NS:
            return None
        w_ns = nxt
    return None


def response_times(flows: list[Flow], tau_ns: int) -> list[Response]:
    """Every flow's worst-case response time by the revised analysis, highest priority first."""
    ordered = sorted(flows, key=lambda flow: flow.priority)
    if len({flow.priority for flow in ordered}) != len(ordered):
        raise ConfigurationError("two messages share one identifier: arbitration cannot order them")
    return [_response(i, ordered, tau_ns) for i in range(len(ordered))]


def _response(index: int, ordered: list[Flow], tau_ns: int) -> Response:
    flow, hp = ordered[index], ordered[:index]
    b_ns = max((k.c_ns for k in ordered[index + 1 :]), default=0)
    busy_ns = busy_period_ns(flow, [*hp, flow], b_ns)
    if busy_ns is None:
        return Response(flow, b_ns, None, 0, None, 0)
    instances = _ceil_div(busy_ns + flow.j_ns, flow.t_ns)
    worst_ns, worst_q = -1, 0
    for q in range(instances):
        w_ns = queuing_delay_ns(flow, hp, b_ns, q, tau_ns)
        if w_ns is None:
            return Response(flow, b_ns, busy_ns, instances, None, q)
        r_ns = flow.j_ns + w_ns - q * flow.t_ns + flow.c_ns
        if r_ns > worst_ns:
            worst_ns, worst_q = r_ns, q
    return Response(flow, b_ns, busy_ns, instances, worst_ns, worst_q)


# --- messages of a bus: from a DBC, or added on the command line -------------------------------


@dataclass(frozen=True)
class BusMessage:
    """A message as the bus schedule needs it; times in ns.

    ``period_ns`` is the cycle time of a cyclic message, or the minimum inter-arrival time of a
    sporadic one (``cyclic`` False; ``assumption`` says where that time came from).
    """

    name: str
    can_id: int
    extended: bool
    dlc: int
    senders: tuple[str, ...]
    period_ns: int
    deadline_ns: int
    cyclic: bool = True
    assumption: str = ""
    frames_per_cycle: int = 1  # frames queued at once each period (the DBC's E2EFramesPerCycle)


def jitter_ns(message: BusMessage, ticks_ns: dict[str, int], queue_jitter_ns: int) -> int:
    """J_m from the sender's tick: how late after its nominal release a frame can be queued.

    A tick-driven sender queues a cyclic frame at the first tick at or after it falls due. When the
    cycle is a multiple of the tick the frame is queued strictly periodically (no jitter); otherwise
    the tick's quantisation delays it by up to ``tick - gcd(cycle, tick)``. A sporadic frame is
    taken to be released by the sender's own software in a tick (a command, an acknowledgement) and
    so queued in that tick. ``queue_jitter_ns`` adds the spread of the moment within a tick at which
    the sender queues its frames. With several senders, the worst of them.
    """
    worst_ns = 0
    if message.cyclic:
        for sender in message.senders:
            tick_ns = ticks_ns[sender]
            worst_ns = max(worst_ns, tick_ns - math.gcd(message.period_ns, tick_ns))
    return worst_ns + queue_jitter_ns


def default_ticks_ns(messages: list[BusMessage]) -> dict[str, int]:
    """Each sender's tick period: the shortest cycle among its cyclic messages.

    A sender of sporadic messages only gets the shortest of their inter-arrival times (its tick
    does not enter their jitter).
    """
    ticks: dict[str, int] = {}
    for message in sorted(messages, key=lambda m: not m.cyclic):  # cyclic ones first
        for sender in message.senders:
            if sender not in ticks or message.cyclic:
                ticks[sender] = min(ticks.get(sender, message.period_ns), message.period_ns)
    return ticks


@dataclass(frozen=True)
class BusLoad:
    """The schedule of one bus at one bitrate: utilization and every message's response."""

    bitrate: int
    messages: list[BusMessage]  # highest priority first
    responses: list[Response]  # same order; a message of several frames: its last frame's
    ticks_ns: dict[str, int]
    queue_jitter_ns: int
    frames: list[Response] = field(default_factory=list)  # every frame of a cycle, by priority

    @property
    def utilization(self) -> float:
        """Sum of C/T over every frame, sporadic ones at their minimum inter-arrival time."""
        return utilization([response.flow for response in self.frames])

    @property
    def schedulable(self) -> bool:
        """True when every message meets its deadline in the worst case."""
        return all(response.meets_deadline for response in self.responses)

    def worst_slack(self) -> tuple[str, int | None]:
        """The message with the least slack and that slack (None: an unbounded response)."""
        unbounded = [r.flow.name for r in self.responses if r.slack_ns is None]
        if unbounded:
            return unbounded[0], None
        worst = min(self.responses, key=lambda r: r.slack_ns or 0)
        return worst.flow.name, worst.slack_ns

    def _cyclic_names(self) -> set[str]:
        return {m.name for m in self.messages if m.cyclic}

    def as_dict(self) -> dict[str, Any]:
        """The JSON report: times in ms, the assumptions spelled out."""
        name, slack_ns = self.worst_slack()
        return {
            "bitrate": self.bitrate,
            "bit_time_us": bit_time_ns(self.bitrate) / 1000,
            "utilization": self.utilization,
            "utilization_cyclic": utilization(
                [r.flow for r in self.frames if r.flow.name in self._cyclic_names()]
            ),
            "schedulable": self.schedulable,
            "worst_slack_message": name,
            "worst_slack_ms": _ms(slack_ns),
            "sender_tick_ms": {node: _ms(tick) for node, tick in sorted(self.ticks_ns.items())},
            "queue_jitter_ms": _ms(self.queue_jitter_ns),
            "analysis": "Davis, Burns, Bril & Lukkien 2007, Real-Time Systems 35:239-272, §4",
            "messages": [
                _message_dict(m, r) for m, r in zip(self.messages, self.responses, strict=True)
            ],
        }


def _ms(value_ns: int | None) -> float | None:
    return None if value_ns is None else value_ns / NS_PER_MS


def _message_dict(message: BusMessage, response: Response) -> dict[str, Any]:
    flow = response.flow
    return {
        "name": message.name,
        "id": message.can_id,
        "extended": message.extended,
        "senders": list(message.senders),
        "dlc": message.dlc,
        "bits": frame_bits(message.dlc, extended=message.extended),
        "frames_per_cycle": message.frames_per_cycle,
        "kind": "cyclic" if message.cyclic else "sporadic",
        "assumption": message.assumption or None,
        "period_ms": _ms(flow.t_ns),
        "deadline_ms": _ms(flow.d_ns),
        "c_ms": _ms(flow.c_ns),
        "j_ms": _ms(flow.j_ns),
        "b_ms": _ms(response.b_ns),
        "r_ms": _ms(response.r_ns),
        "slack_ms": _ms(response.slack_ns),
        "busy_period_ms": _ms(response.busy_ns),
        "instances": response.instances,
        "worst_instance": response.worst_instance,
        "meets_deadline": response.meets_deadline,
    }


def analyse_bus(
    messages: list[BusMessage],
    bitrate: int,
    *,
    ticks_ns: dict[str, int] | None = None,
    queue_jitter_ns: int = 0,
) -> BusLoad:
    """The revised analysis of ``messages`` at ``bitrate``; utilization over 100 % is an error.

    ``ticks_ns`` overrides the senders' tick periods (default: ``default_ticks_ns``). A message of
    ``frames_per_cycle`` n > 1 is n flows: its frames are queued at once each period and leave
    in order, the k-th behind the k - 1 before it (its priority just below theirs, above every
    other identifier's), each with the message's period, deadline and jitter; the message's
    response is its last frame's (every frame's in ``BusLoad.frames``).
    """
    tau_ns = bit_time_ns(bitrate)
    ticks = default_ticks_ns(messages) | (ticks_ns or {})
    flows = [_flow(m, k, tau_ns, ticks, queue_jitter_ns)
             for m in messages for k in range(m.frames_per_cycle)]
    load = utilization(flows)
    if load > 1.0:
        raise ConfigurationError(
            f"utilization {load:.1%} > 100 % at {bitrate} bit/s: the bus cannot carry these "
            "messages (use a higher --bitrate)"
        )
    frames = response_times(flows, tau_ns)
    by_name = {m.name: m for m in messages}
    last = [r for r in frames if r.flow.priority % MAX_FRAMES_PER_CYCLE
            == by_name[r.flow.name].frames_per_cycle - 1]
    ordered = [by_name[r.flow.name] for r in last]
    return BusLoad(bitrate, ordered, last, ticks, queue_jitter_ns, frames)


def _flow(message: BusMessage, k: int, tau_ns: int, ticks: dict[str, int],
          queue_jitter_ns: int) -> Flow:
    """Frame ``k`` of ``message``'s cycle as a flow."""
    key = arbitration_key(message.can_id, extended=message.extended)
    return Flow(
        name=message.name,
        priority=key * MAX_FRAMES_PER_CYCLE + k,
        c_ns=frame_bits(message.dlc, extended=message.extended) * tau_ns,
        t_ns=message.period_ns,
        d_ns=message.deadline_ns,
        j_ns=jitter_ns(message, ticks, queue_jitter_ns),
    )


# --- reading the messages from a DBC -----------------------------------------------------------

DEADLINE_ATTRIBUTE = "GenMsgDeadlineTime"  # ms; odocan's convention, default: the cycle time
FRAMES_ATTRIBUTE = "E2EFramesPerCycle"  # frames sent each cycle (dbc/README.md), default 1
DELAY_ATTRIBUTE = "GenMsgDelayTime"  # ms; Vector's minimum time between two sends


def ms_to_ns(value_ms: str | float | int, what: str, *, allow_zero: bool = False) -> int:
    """A positive (or zero) time in ms, text or number, as whole ns; else a one-line error."""
    try:
        ns = Decimal(str(value_ms).strip()) * NS_PER_MS
    except InvalidOperation:
        raise ConfigurationError(f"{what}: {value_ms!r} is not a number of ms") from None
    low = 0 if allow_zero else 1
    if not ns.is_finite() or ns < low or ns != ns.to_integral_value():
        kind = "a time" if allow_zero else "a positive time"
        raise ConfigurationError(f"{what}: {value_ms!r} must be {kind} in ms, in whole ns")
    return int(ns)


def messages_from_dbc(db: Database, *, sporadic_ms: str | float | None = None) -> list[BusMessage]:
    """Every frame of ``db`` as a ``BusMessage``.

    A message with a ``GenMsgCycleTime`` is cyclic with that period. One without is sporadic: its
    minimum inter-arrival time is its ``GenMsgDelayTime`` when the DBC gives one, else
    ``sporadic_ms``, else the DBC's shortest cycle time (as if the event could recur as often as
    the fastest cyclic traffic). The deadline is ``GenMsgDeadlineTime`` when given, else the period.
    """
    cycles = [m.cycle_time for m in db.messages if m.cycle_time]
    if sporadic_ms is not None:
        fallback_ns, source = ms_to_ns(sporadic_ms, "--sporadic-ms"), "--sporadic-ms"
    elif cycles:
        fallback_ns, source = min(cycles) * NS_PER_MS, "the DBC's shortest cycle time"
    else:
        fallback_ns, source = 0, ""
    return [_bus_message(message, fallback_ns, source) for message in db.messages]


def _bus_message(message: Message, fallback_ns: int, source: str) -> BusMessage:
    if message.is_fd or message.length > MAX_DLC:
        raise ConfigurationError(f"{message.name}: CAN FD frames are not covered by this analysis")
    attributes = message.dbc.attributes if message.dbc is not None else {}
    where = f"{message.name} {DEADLINE_ATTRIBUTE}"
    cycle_ms, assumption = message.cycle_time, ""
    cyclic = bool(cycle_ms)
    if cycle_ms:
        period_ns = ms_to_ns(cycle_ms, f"{message.name} GenMsgCycleTime")
    elif DELAY_ATTRIBUTE in attributes and attributes[DELAY_ATTRIBUTE].value:
        period_ns = ms_to_ns(attributes[DELAY_ATTRIBUTE].value, f"{message.name} {DELAY_ATTRIBUTE}")
        assumption = f"no cycle time: sporadic, min inter-arrival = its {DELAY_ATTRIBUTE}"
    elif fallback_ns:
        period_ns = fallback_ns
        assumption = f"no cycle time: sporadic, min inter-arrival = {source}"
    else:
        raise ConfigurationError(
            f"{message.name} has no cycle time and the DBC none to assume: give --sporadic-ms"
        )
    deadline_ns = period_ns
    if DEADLINE_ATTRIBUTE in attributes and attributes[DEADLINE_ATTRIBUTE].value:
        deadline_ns = ms_to_ns(attributes[DEADLINE_ATTRIBUTE].value, where)
    return BusMessage(
        name=message.name,
        can_id=message.frame_id,
        extended=message.is_extended_frame,
        dlc=message.length,
        senders=tuple(message.senders) or ("(no sender)",),
        period_ns=period_ns,
        deadline_ns=deadline_ns,
        cyclic=cyclic,
        assumption=assumption,
        frames_per_cycle=_frames_per_cycle(message.name, attributes),
    )


def _frames_per_cycle(name: str, attributes: dict[str, Any]) -> int:
    """The message's ``E2EFramesPerCycle`` (1 without it); 1 .. 16, else a one-line error."""
    if FRAMES_ATTRIBUTE not in attributes:
        return 1
    value = attributes[FRAMES_ATTRIBUTE].value
    if isinstance(value, bool) or not isinstance(value, int) or not (
            1 <= value <= MAX_FRAMES_PER_CYCLE):
        raise ConfigurationError(f"{name} {FRAMES_ATTRIBUTE}: {value!r} is not a whole number "
                                 f"of frames in 1..{MAX_FRAMES_PER_CYCLE}")
    return value
