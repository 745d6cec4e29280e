"""The CAN response-time analysis (host.judge.schedulability) against independent references.

Davis, Burns, Bril & Lukkien (2007), "Controller Area Network (CAN) schedulability analysis:
refuted, revisited and revised", Real-Time Systems 35:239-272.

* Frame lengths: the field widths of a CAN 2.0 data frame (ISO 11898-1) summed here, and the
  worst-case number of stuff bits found by exhaustive search over short bit strings.
* Response times: a discrete-event simulation of non-preemptive fixed-priority arbitration written
  below, independent of the analysis. Every response it produces, under random phasings and
  jitters, is within the analysis' bound; from the critical instant the bound is reached within
  one bit time.
* The three-message example of Davis et al. §3, on which Tindell's original analysis (kept here,
  in the test, as the reference that fails) is optimistic: the revised analysis and the simulation
  both find the second instance of the lowest-priority message missing its deadline.

We could not recover the published response-time tables of the SAE benchmark with certainty, so
no figure of them is asserted here; the simulation stands in as the independent reference.
"""

from __future__ import annotations

import heapq
import itertools
import random
from dataclasses import dataclass

import pytest

from odocan.host.judge import schedulability as sched
from odocan.host.judge.schedulability import Flow, Response, response_times
from odocan.sim.contract import database
from odocan.sim.exceptions import ConfigurationError

MS = 1_000_000  # ns
US = 1_000

# ISO 11898-1 data frame fields, in order, with their widths in bits.
STANDARD_STUFFED = {"SOF": 1, "ID": 11, "RTR": 1, "IDE": 1, "r0": 1, "DLC": 4, "CRC": 15}
EXTENDED_STUFFED = {
    "SOF": 1, "ID_A": 11, "SRR": 1, "IDE": 1, "ID_B": 18, "RTR": 1, "r1": 1, "r0": 1, "DLC": 4,
    "CRC": 15,
}  # fmt: skip
NOT_STUFFED = {"CRC_delimiter": 1, "ACK_slot": 1, "ACK_delimiter": 1, "EOF": 7, "IFS": 3}


# --- frame lengths ---------------------------------------------------------------------------


def stuff_bits(bits: list[int]) -> int:
    """Stuff bits CAN inserts into ``bits``: one after every 5 equal bits (stuff bits included)."""
    count, run_bit, run = 0, -1, 0
    for bit in bits:
        run = run + 1 if bit == run_bit else 1
        run_bit = bit
        if run == 5:
            count += 1
            run_bit, run = 1 - bit, 1  # the complement, which starts the next run
    return count


def test_stuffing_counter_on_known_strings() -> None:
    assert stuff_bits([1] * 5) == 1
    assert stuff_bits([1] * 4) == 0
    assert stuff_bits([1] * 5 + [0] * 4) == 2  # the stuffed 0 and four 0s make five
    assert stuff_bits([1, 0] * 20) == 0


@pytest.mark.parametrize("n", range(1, 15))
def test_worst_case_stuff_bits_by_exhaustive_search(n: int) -> None:
    """Over every string of n bits the most stuff bits is floor((n - 1) / 4), the §2 bound."""
    worst = max(stuff_bits(list(bits)) for bits in itertools.product((0, 1), repeat=n))
    assert worst == (n - 1) // 4


@pytest.mark.parametrize("n", [34, 54, 98, 118])
def test_worst_case_stuff_bits_reached_by_five_then_fours(n: int) -> None:
    """11111 0000 1111 0000 ...: a stuff bit after the first five bits, then after every four."""
    pattern = [1] * 5 + [(k // 4) % 2 for k in range(n - 5)]
    assert stuff_bits(pattern) == (n - 1) // 4


@pytest.mark.parametrize("extended", [False, True])
@pytest.mark.parametrize("dlc", range(9))
def test_frame_bits_from_the_field_widths(dlc: int, extended: bool) -> None:
    stuffed = sum((EXTENDED_STUFFED if extended else STANDARD_STUFFED).values()) + 8 * dlc
    expected = stuffed + (stuffed - 1) // 4 + sum(NOT_STUFFED.values())
    assert sched.frame_bits(dlc, extended=extended) == expected
    if not extended:
        assert expected == 55 + 10 * dlc  # the closed form for 11-bit identifiers


def test_frame_bits_refuses_can_fd_lengths() -> None:
    with pytest.raises(ConfigurationError, match="DLC 9"):
        sched.frame_bits(9, extended=False)


def test_bit_times_and_non_can_bitrates() -> None:
    assert [sched.bit_time_ns(rate) * rate for rate in sched.BITRATES] == [10**9] * 9
    with pytest.raises(ConfigurationError, match="not a CAN bitrate"):
        sched.bit_time_ns(115_200)


def test_arbitration_order() -> None:
    """Lower ID first; a standard frame beats an extended one with the same 11-bit base."""
    keys = [
        sched.arbitration_key(0x100, extended=False),
        sched.arbitration_key(0x100 << 18, extended=True),
        sched.arbitration_key((0x100 << 18) | 1, extended=True),
        sched.arbitration_key(0x101, extended=False),
    ]
    assert keys == sorted(keys)
    assert len(set(keys)) == 4


# --- an independent simulation of CAN arbitration --------------------------------------------


@dataclass(frozen=True)
class Instance:
    flow: int  # index into the priority-ordered flows
    release_ns: int  # nominal release
    queued_ns: int  # release + this instance's jitter


def simulate(
    flows: list[Flow], instances: list[Instance], busy_until_ns: int, late_join_ns: int = 0
) -> list[int]:
    """Worst simulated response per flow (-1: none sent); ``flows`` highest priority first.

    The bus is busy until ``busy_until_ns`` (a lower-priority frame that started just before 0).
    Whenever it goes idle, the highest-priority frame queued by then wins and holds the bus for
    its whole C (non-preemptive); responses run from the nominal release to the end of the frame.
    ``late_join_ns`` > 0 also lets frames queued less than that after the idle instant join the
    arbitration (starting when queued): the window the analysis' tau_bit term covers.
    """
    pending = sorted(instances, key=lambda inst: inst.queued_ns)
    ready: list[tuple[int, int, int, Instance]] = []
    worst = [-1] * len(flows)
    t_ns, i = busy_until_ns, 0
    while i < len(pending) or ready:
        while i < len(pending) and pending[i].queued_ns < t_ns + max(1, late_join_ns):
            inst = pending[i]
            heapq.heappush(ready, (flows[inst.flow].priority, inst.queued_ns, i, inst))
            i += 1
        if not ready:
            t_ns = pending[i].queued_ns
            continue
        inst = heapq.heappop(ready)[3]
        t_ns = max(t_ns, inst.queued_ns) + flows[inst.flow].c_ns
        worst[inst.flow] = max(worst[inst.flow], t_ns - inst.release_ns)
    return worst


def critical_instant(flows: list[Flow], m: int, horizon_ns: int) -> tuple[list[Instance], int]:
    """§4's worst case for flow m: every hep(m) flow queued at 0 after its full jitter, then as
    early as its period allows; the longest lower-priority frame just started."""
    instances = []
    for k, flow in enumerate(flows[: m + 1]):
        instances.append(Instance(k, -flow.j_ns, 0))
        for n in itertools.count(1):
            release_ns = n * flow.t_ns - flow.j_ns
            if release_ns > horizon_ns:
                break
            instances.append(Instance(k, release_ns, release_ns))
    blocking_ns = max((flow.c_ns for flow in flows[m + 1 :]), default=0)
    return instances, blocking_ns


def random_phasing(flows: list[Flow], rng: random.Random, horizon_ns: int) -> list[Instance]:
    """Every flow with a random offset, each instance with a random jitter in [0, J]."""
    instances = []
    for k, flow in enumerate(flows):
        release_ns = rng.randrange(flow.t_ns)
        while release_ns < horizon_ns:
            instances.append(Instance(k, release_ns, release_ns + rng.randint(0, flow.j_ns)))
            release_ns += flow.t_ns
    return instances


def random_flows(rng: random.Random, tau_ns: int) -> list[Flow]:
    """3-8 flows with frame-shaped C, periods 2-20 ms, jitter up to a quarter period, U < 0.95."""
    while True:
        flows = []
        for k in range(rng.randint(3, 8)):
            t_ns = rng.choice([2, 2.5, 3, 4, 5, 7, 10, 20]) * MS
            c_ns = sched.frame_bits(rng.randint(0, 8), extended=rng.random() < 0.3) * tau_ns
            j_ns = rng.choice([0, rng.randrange(int(t_ns) // 4)])
            flows.append(Flow(f"m{k}", k, c_ns, int(t_ns), int(t_ns), j_ns))
        if sched.utilization(flows) < 0.95:
            return flows


def analysed(flows: list[Flow], tau_ns: int) -> list[Response]:
    responses = response_times(flows, tau_ns)
    assert [r.flow for r in responses] == sorted(flows, key=lambda flow: flow.priority)
    return responses


def assert_reached_from_critical_instant(flows: list[Flow], tau_ns: int) -> None:
    """For every flow: simulated from its critical instant, R - tau < simulated <= R."""
    for m, response in enumerate(analysed(flows, tau_ns)):
        assert response.r_ns is not None
        assert response.busy_ns is not None
        instances, blocking_ns = critical_instant(flows, m, response.busy_ns)
        simulated = simulate(flows, instances, blocking_ns)[m]
        assert response.r_ns - tau_ns < simulated <= response.r_ns, flows[m].name


@pytest.mark.parametrize("seed", range(40))
def test_analysis_bounds_every_simulated_response(seed: int) -> None:
    rng = random.Random(seed)
    tau_ns = sched.bit_time_ns(125_000)
    flows = random_flows(rng, tau_ns)
    bounds = [r.r_ns for r in analysed(flows, tau_ns)]
    for _ in range(5):
        worst = simulate(flows, random_phasing(flows, rng, 200 * MS), 0)
        for flow, simulated, bound in zip(flows, worst, bounds, strict=True):
            assert bound is not None, flow.name
            assert simulated <= bound, flow.name
    for m, flow in enumerate(flows):  # and from each flow's critical instant
        busy_ns = analysed(flows, tau_ns)[m].busy_ns
        assert busy_ns is not None
        simulated = simulate(flows, *critical_instant(flows, m, busy_ns))[m]
        assert simulated <= (bounds[m] or 0), flow.name


@pytest.mark.parametrize("seed", range(100))
def test_bound_is_tight_up_to_the_tau_window(seed: int) -> None:
    """From every flow's critical instant the simulation reaches the bound within a bit time; where
    it does not, the gap is the tau_bit term: a higher-priority frame queued within a bit of the
    arbitration is counted, and letting such frames join reaches the bound within a bit time.
    (Over seeds 0-299 that second case is 3 flows of 1222.)"""
    tau_ns = sched.bit_time_ns(125_000)
    flows = random_flows(random.Random(seed), tau_ns)
    for m, response in enumerate(analysed(flows, tau_ns)):
        assert response.r_ns is not None
        assert response.busy_ns is not None
        instances, blocking_ns = critical_instant(flows, m, response.busy_ns)
        simulated = simulate(flows, instances, blocking_ns)[m]
        assert simulated <= response.r_ns
        if response.r_ns - simulated >= tau_ns:
            joined = simulate(flows, instances, blocking_ns, late_join_ns=tau_ns)[m]
            assert abs(joined - response.r_ns) < tau_ns, (flows[m].name, simulated, joined)


@pytest.mark.parametrize("bitrate", [125_000, 250_000, 500_000, 1_000_000])
def test_bound_reached_on_odocan_dbc(bitrate: int) -> None:
    messages = sched.messages_from_dbc(database())
    load = sched.analyse_bus(messages, bitrate)
    assert_reached_from_critical_instant(  # every frame: ODOM_STATUS's 2, SIM_TRUTH's 3
        [r.flow for r in load.frames], sched.bit_time_ns(bitrate)
    )


def test_bound_reached_on_a_loaded_set_with_jitter_and_several_instances() -> None:
    """Utilization 94.5 %, jitters, and a lowest-priority message whose worst instance is its
    third of eight: the bound is still reached from the critical instant, within a bit time."""
    tau_ns = sched.bit_time_ns(125_000)
    c4, c8 = (sched.frame_bits(dlc, extended=False) * tau_ns for dlc in (4, 8))
    flows = [
        Flow("a", 1, c4, 5 * MS, 5 * MS, 1 * MS),
        Flow("b", 2, c8, 4 * MS, 4 * MS, 1 * MS),
        Flow("c", 3, c8, 4 * MS, 4 * MS, 1 * MS),
        Flow("d", 4, c4, 3 * MS, 3 * MS, 250 * US),
    ]
    assert sched.utilization(flows) == pytest.approx(0.945, abs=1e-3)
    d = analysed(flows, tau_ns)[-1]
    assert (d.instances, d.worst_instance) == (8, 2)
    assert_reached_from_critical_instant(flows, tau_ns)


# --- Davis et al. §3: where Tindell's original analysis is optimistic ------------------------


def tindell_1994_ns(flows: list[Flow], tau_ns: int) -> list[int]:
    """The original analysis (Davis et al. §3): the first instance only,
    R = J + w + C, w = B + sum_{hp} ceil((w + J_k + tau) / T_k) C_k. Refuted; kept as a foil."""
    ordered = sorted(flows, key=lambda flow: flow.priority)
    result = []
    for m, flow in enumerate(ordered):
        b_ns = max((k.c_ns for k in ordered[m + 1 :]), default=0)
        w_ns, nxt = -1, b_ns
        while nxt != w_ns:
            w_ns = nxt
            nxt = b_ns + sum(-(-(w_ns + k.j_ns + tau_ns) // k.t_ns) * k.c_ns for k in ordered[:m])
        result.append(flow.j_ns + w_ns + flow.c_ns)
    return result


# Davis et al. 2007 §3, the example message set as we recall it (not checked against a copy of the
# paper): three messages of 125 bits (1 ms at 125 kbit/s), A: T = D = 2.5 ms; B and C: T = 3.5 ms,
# D = 3.25 ms; no jitter. The paper's point holds here independently of the recollection: the
# simulation below shows C's second instance answering in 3.5 ms, which Tindell's analysis misses.
DAVIS_TAU_NS = sched.bit_time_ns(125_000)
DAVIS_SET = [
    Flow("A", 1, 1 * MS, 2500 * US, 2500 * US),
    Flow("B", 2, 1 * MS, 3500 * US, 3250 * US),
    Flow("C", 3, 1 * MS, 3500 * US, 3250 * US),
]


def test_davis_example_tindell_analysis_is_optimistic() -> None:
    assert tindell_1994_ns(DAVIS_SET, DAVIS_TAU_NS) == [2 * MS, 3 * MS, 3 * MS]  # all "meet" D


def test_davis_example_revised_analysis_finds_the_miss() -> None:
    a, b, c = analysed(DAVIS_SET, DAVIS_TAU_NS)
    assert (a.r_ns, b.r_ns) == (2 * MS, 3 * MS)
    assert c.busy_ns == 7 * MS
    assert c.instances == 2
    assert c.worst_instance == 1
    assert c.r_ns == 3500 * US  # the second instance, 3.5 ms > 3.25 ms
    assert not c.meets_deadline
    assert c.slack_ns == -250 * US
    assert a.meets_deadline
    assert b.meets_deadline


def test_davis_example_simulated_second_instance_misses() -> None:
    instances, blocking_ns = critical_instant(DAVIS_SET, 2, 7 * MS)
    assert blocking_ns == 0
    assert simulate(DAVIS_SET, instances, blocking_ns)[2] == 3500 * US  # C's second instance
    assert_reached_from_critical_instant(DAVIS_SET, DAVIS_TAU_NS)


# --- unbounded and malformed sets -------------------------------------------------------------


def test_full_bus_is_unbounded_and_misses() -> None:
    """a and b fill the bus; with a lower frame to block b, b's busy period never ends."""
    flows = [
        Flow("a", 1, 1 * MS, 2 * MS, 2 * MS),
        Flow("b", 2, 1 * MS, 2 * MS, 2 * MS),
        Flow("c", 3, 1 * MS, 1000_000 * MS, 1000_000 * MS),
    ]
    a, b, c = analysed(flows, DAVIS_TAU_NS)
    assert a.meets_deadline
    assert a.r_ns == 2 * MS
    assert b.busy_ns is None
    assert b.r_ns is None
    assert b.slack_ns is None
    assert not b.meets_deadline
    assert c.r_ns is None
    assert b.b_ns == 1 * MS


def test_full_bus_without_blocking_is_bounded() -> None:
    """Utilization exactly 1 and nothing below: the lowest message still gets through."""
    flows = [Flow("a", 1, 1 * MS, 2 * MS, 2 * MS), Flow("b", 2, 1 * MS, 2 * MS, 2 * MS)]
    assert [r.r_ns for r in analysed(flows, DAVIS_TAU_NS)] == [2 * MS, 2 * MS]


def test_shared_identifier_is_refused() -> None:
    with pytest.raises(ConfigurationError, match="share one identifier"):
        response_times([Flow("a", 1, MS, 2 * MS, 2 * MS), Flow("b", 1, MS, 3 * MS, 3 * MS)], 1)


# --- the DBC side -----------------------------------------------------------------------------


def test_odocan_dbc_utilization_by_hand() -> None:
    """17 frames of 8 bytes, 135 bits each: 1 at 10 ms, 4 at 20 ms, 6 at 100 ms (NAV_STATUS, 2 of
    ODOM_STATUS and 3 of SIM_TRUTH: their E2EFramesPerCycle), 1 at 1000 ms (ODOM_FRESHNESS), and
    5 event messages taken as sporadic at the DBC's shortest cycle."""
    messages = sched.messages_from_dbc(database())
    load = sched.analyse_bus(messages, 500_000)
    frame_ms = 135 * 2e-3
    assert load.utilization == pytest.approx(
        frame_ms * (6 / 10 + 4 / 20 + 6 / 100 + 1 / 1000), rel=1e-12)
    sporadic = [m.name for m in messages if not m.cyclic]
    assert sporadic == ["NAV_GOAL", "ODOM_SET_POSE", "ODOM_CONFIG", "ODOM_ACK", "ODOM_AUTH"]
    assert all("shortest cycle" in m.assumption for m in messages if not m.cyclic)
    wheel = load.responses[0]
    assert wheel.flow.name == "WHEEL_ENCODERS"
    assert (wheel.b_ns, wheel.r_ns) == (270 * US, 540 * US)  # one lower frame, then itself


def test_jitter_from_the_senders_tick() -> None:
    message = sched.BusMessage("M", 0x10, False, 8, ("N",), 25 * MS, 25 * MS)
    assert sched.jitter_ns(message, {"N": 10 * MS}, 0) == 5 * MS  # 10 - gcd(25, 10)
    assert sched.jitter_ns(message, {"N": 5 * MS}, 0) == 0  # 25 is a multiple of the tick
    assert sched.jitter_ns(message, {"N": 5 * MS}, 100 * US) == 100 * US
    event = sched.BusMessage("E", 0x11, False, 8, ("N",), 25 * MS, 25 * MS, cyclic=False)
    assert sched.jitter_ns(event, {"N": 10 * MS}, 0) == 0  # queued in the tick that makes it


def test_default_ticks_are_the_shortest_cycles() -> None:
    ticks = sched.default_ticks_ns(sched.messages_from_dbc(database()))
    assert ticks == {"MOTOR_CTRL": 10 * MS, "ODOM_MCU": 20 * MS, "HOST": 20 * MS, "SIM": 100 * MS}


def test_overload_is_refused() -> None:
    with pytest.raises(ConfigurationError, match=r"utilization .* > 100 % at 50000 bit/s"):
        sched.analyse_bus(sched.messages_from_dbc(database()), 50_000)


@pytest.mark.parametrize("text", ["0", "-1", "abc", "1e-7", "nan", "inf"])
def test_ms_to_ns_refuses(text: str) -> None:
    with pytest.raises(ConfigurationError, match="--x"):
        sched.ms_to_ns(text, "--x")


def test_ms_to_ns_is_exact() -> None:
    assert sched.ms_to_ns("2.5", "x") == 2_500_000
    assert sched.ms_to_ns("0.000001", "x") == 1
    assert sched.ms_to_ns("0", "x", allow_zero=True) == 0
