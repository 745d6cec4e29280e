"""The bit-timed transport's measured latencies never exceed the analysis' worst-case R.

The traffic runs on the real wire (``sim.transport.OdocanBus`` with a bitrate: arbitration by ID,
exact stuffed lengths, the wire's own ``LatencyStats``); R comes from
``host.judge.schedulability.analyse_bus`` / ``response_times``. Two kinds of check:

* a sweep over bitrates (125k, 250k, 500k, 1M) and message sets (odocan.dbc, its event messages
  at ``--sporadic-ms 100``; odocan.dbc with
  messages added as ``odocan busload --add`` adds them; odocan.dbc with a babbling node at ID 0x001
  sending 8-byte frames as fast as 40 % of the bus): every message released periodically
  (sporadic ones at their minimum inter-arrival time) from seeded random phases on a 10 ms grid,
  each frame queued up to 32 bit times late (the analysis' queuing jitter), random payloads;
  the measured maximum of every message is within its R;
* a constructed critical instant: the lowest-priority frame starts a hundredth of a bit before
  every other message is queued at once; R (computed with the frames' actual lengths, their
  interframe space included) is then reached within one bit time: the measured latency (queued
  to end of frame, so without the 3-bit interframe space R counts) plus 3 bits lies in
  [R - 1 bit, R].
"""

from __future__ import annotations

import itertools
import math
import random

import can
import pytest

from odocan.host.cli.subparsers.busload import parse_added
from odocan.host.judge.schedulability import (
    NS_PER_S,
    BusMessage,
    Flow,
    analyse_bus,
    arbitration_key,
    messages_from_dbc,
    response_times,
)
from odocan.sim.canbits import INTERFRAME_BITS, LatencyStats, frame_bits
from odocan.sim.contract import database
from odocan.sim.transport import OdocanBus

BITRATES = (125_000, 250_000, 500_000, 1_000_000)
SPORADIC_MS = "100"  # the event messages' minimum inter-arrival (at 10 ms 125k is over 100 %)
JITTER_BITS = 32  # each frame is queued up to 32 bit times after its nominal release (J)
TICK_NS = 10_000_000
_channels = itertools.count()


def _run_wire(
    releases: list[tuple[int, str, can.Message]], bitrate: int, end_ns: int
) -> LatencyStats:
    """Send each (release ns, sender node, frame) from its node's handle on a fresh bit-timed
    wire, in time order, running the wire up to each release; then to ``end_ns``."""
    channel = f"buslat-{next(_channels)}"
    nodes = sorted({node for _, node, _ in releases})
    buses = {
        node: OdocanBus(channel, bitrate=bitrate, preserve_timestamps=True, rx_queue_size=1,
                        clock=lambda: 0.0)
        for node in nodes
    }
    try:
        timing = buses[nodes[0]].timing
        assert timing is not None
        for release_ns, node, msg in sorted(releases, key=lambda r: (r[0], r[2].arbitration_id)):
            timing.run_until(release_ns / NS_PER_S)
            msg.timestamp = release_ns / NS_PER_S
            buses[node].send(msg)
        timing.run_until(end_ns / NS_PER_S)
        assert not timing.pending, "the wire must have carried every frame"
        return timing.latency
    finally:
        for bus in buses.values():
            bus.shutdown()


def _periodic_releases(
    messages: list[BusMessage], duration_ns: int, jitter_ns: int, rng: random.Random
) -> list[tuple[int, str, can.Message]]:
    out = []
    for m in messages:  # phases on the 10 ms tick grid, as the rig has them: frames collide
        phase_ns = rng.randrange(max(1, m.period_ns // TICK_NS)) * TICK_NS
        for nominal_ns in range(phase_ns, duration_ns, m.period_ns):
            release_ns = nominal_ns + rng.randrange(jitter_ns + 1)
            for _ in range(m.frames_per_cycle):  # ODOM_STATUS 2, SIM_TRUTH 3: queued at once
                data = rng.randbytes(m.dlc)
                msg = can.Message(arbitration_id=m.can_id, is_extended_id=m.extended, data=data)
                out.append((release_ns, m.senders[0], msg))
    return out


def _babbler(bitrate: int) -> BusMessage:
    """ID 0x001, 8 bytes, as often as 40 % of the bus (worst-case length), whole us."""
    tau_ns = NS_PER_S // bitrate
    period_us = math.ceil(135 * tau_ns / 0.4 / 1000)
    return parse_added(f"BABBLE:0x001:8:{period_us / 1000}")


def _message_set(kind: str, bitrate: int) -> list[BusMessage]:
    messages = messages_from_dbc(database(), sporadic_ms=SPORADIC_MS)
    if kind == "dbc+added":
        messages += [parse_added("EXTRA_FAST:0x0F0:8:5"), parse_added("EXTRA_EXT:0x18FF0010:8:20")]
    elif kind == "dbc+babbler":
        messages += [_babbler(bitrate)]
    return messages


@pytest.mark.parametrize("kind", ["dbc", "dbc+added", "dbc+babbler"])
@pytest.mark.parametrize("bitrate", BITRATES)
def test_measured_latency_within_the_analysis_bound(bitrate: int, kind: str) -> None:
    messages = _message_set(kind, bitrate)
    tau_ns = NS_PER_S // bitrate
    jitter_ns = JITTER_BITS * tau_ns
    load = analyse_bus(messages, bitrate, queue_jitter_ns=jitter_ns)
    duration_ns = 3 * NS_PER_S
    rng = random.Random(f"{bitrate}/{kind}")
    stats = _run_wire(
        _periodic_releases(messages, duration_ns, jitter_ns, rng),
        bitrate,
        duration_ns + NS_PER_S,
    )
    assert len(stats.by_id) == len(messages)
    queued = 0  # messages that waited behind another frame at least once
    for m, r in zip(load.messages, load.responses, strict=True):
        assert r.r_ns is not None
        hist = stats.by_id[(m.can_id, m.extended)]
        assert hist.count >= duration_ns // m.period_ns
        measured_ns = hist.max_bits * tau_ns
        assert measured_ns <= r.r_ns, f"{m.name} at {bitrate}: {measured_ns} ns > R {r.r_ns} ns"
        queued += hist.max_bits > frame_bits(_stuffed_frame(m))
    assert queued >= len(messages) // 2, "the phasing never made frames contend: no test"


def _stuffed_frame(m: BusMessage) -> can.Message:
    """``m``'s frame with an all-zero payload (a stuff bit every four data bits)."""
    return can.Message(arbitration_id=m.can_id, is_extended_id=m.extended, data=bytes(m.dlc))


# --- the critical instant: the bound reached within one bit time -----------------------------

# (ID, payload) in priority order; the last one is the blocker. Payloads chosen for stuffing.
_CRITICAL = [
    (0x010, bytes.fromhex("0000000000000000")),
    (0x020, bytes.fromhex("ffffffffffffffff")),
    (0x030, bytes.fromhex("0f0f0f0f0f0f0f0f")),
    (0x040, bytes.fromhex("a5a5a5a5")),
    (0x050, bytes.fromhex("0000000000000000")),  # the longest frame: the analysis' B for all
]


@pytest.mark.parametrize("bitrate", BITRATES)
@pytest.mark.parametrize("fast_period_bits", [None, 300])
def test_critical_instant_reaches_the_bound_within_one_bit(
    bitrate: int, fast_period_bits: int | None
) -> None:
    """Queue everything at once a hundredth of a bit after the blocker started; with
    ``fast_period_bits`` the top message recurs that often (several instances interfere)."""
    tau_ns = NS_PER_S // bitrate
    frames = [can.Message(arbitration_id=i, is_extended_id=False, data=d) for i, d in _CRITICAL]
    bits = [frame_bits(f) + INTERFRAME_BITS for f in frames]
    long_ns = 10 * NS_PER_S // 1000  # 10 ms: one instance each in the busy period
    periods = [long_ns] * len(frames)
    if fast_period_bits is not None:
        periods[0] = fast_period_bits * tau_ns
    flows = [
        Flow(f"m{i:x}", arbitration_key(i, extended=False), b * tau_ns, t, t)
        for (i, _), b, t in zip(_CRITICAL, bits, periods, strict=True)
    ]
    responses = {r.flow.name: r for r in response_times(flows, tau_ns)}

    lead_ns = tau_ns // 100  # the others are queued just after the blocker's start of frame
    releases: list[tuple[int, str, can.Message]] = [(0, "blocker", frames[-1])]
    for k, frame in enumerate(frames[:-1]):
        for release_ns in range(lead_ns, long_ns, periods[k]):
            copy = can.Message(arbitration_id=frame.arbitration_id, is_extended_id=False,
                               data=frame.data)
            releases.append((release_ns, f"node{k}", copy))
    stats = _run_wire(releases, bitrate, 2 * long_ns)

    for (can_id, _), flow in zip(_CRITICAL[:-1], flows[:-1], strict=True):
        r_ns = responses[flow.name].r_ns
        assert r_ns is not None
        measured_ns = (stats.by_id[(can_id, False)].max_bits + INTERFRAME_BITS) * tau_ns
        assert r_ns - tau_ns <= measured_ns <= r_ns, (
            f"{flow.name} at {bitrate}: measured+IFS {measured_ns} ns, R {r_ns} ns"
        )
