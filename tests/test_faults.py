"""The fault injector (sim.faults) and what the firmware's E2E checks make of its faults.

* ``FaultSpec`` text, ``ErrorCounters`` (ISO 11898-1 fault confinement);
* ``FaultInjectingBus`` on python-can virtual buses: each fault, its count, its log line;
* the E2E check against corruption: every single- and double-bit error of every protected frame
  type of the DBC is detected, random multi-bit corruption passes at about 2^-8;
* the lockstep rig with faults on the sim's bus handle (tests/fault_rig.py): the firmware counts
  every fault, its pose stays on the float64 reference, duplicates and replays change nothing,
  bus-off takes it to DEGRADED and back (seen in ODOM_STATUS, decoded by cantools).
"""

from __future__ import annotations

import functools
import itertools
import logging
import random

import can
import pytest

from odocan.firmware import frames as fr
from odocan.firmware.e2e import E2EReceiver, E2EStatus
from odocan.firmware.errors import ErrorFlag, State
from odocan.sim.contract import database
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.faults import FAULT_KINDS, BusOff, ErrorCounters, FaultInjectingBus, FaultSpec
from odocan.sim.scenarios import RandomScenario
from tests import host_frames as hf
from tests.dbc_typed import decode, number
from tests.fault_rig import (
    FaultRig,
    PoseAudit,
    binomial_upper_bound,
    dbc_data_ids,
    dbc_frame_types,
    open_virtual,
    protected_frames,
    unique_channel,
)

COUNTER_BITS = range(8, 12)  # byte 1, bits 0-3: the E2E COUNTER (it also selects the data ID)


# --- FaultSpec ---------------------------------------------------------------------------------
def test_spec_parses_every_key_and_prints_back() -> None:
    text = (
        "drop=0.01,burst=0.002:5,dup=0.005,delay=0.01:15,flip=0.001:3,babble=20,busoff=2:0.5,seed=7"
    )
    spec = FaultSpec.parse(text)
    assert spec == FaultSpec(
        drop=0.01,
        burst=0.002,
        burst_len=5,
        dup=0.005,
        delay=0.01,
        delay_ms=15.0,
        flip=0.001,
        flip_bits=3,
        babble=20.0,
        busoff=BusOff(2.0, 0.5),
        seed=7,
    )
    assert FaultSpec.parse(str(spec)) == spec
    assert FaultSpec.parse(" flip = 0.5 ").flip_bits == 1
    assert not FaultSpec.parse("").active
    assert not FaultSpec.parse("seed=3").active
    assert spec.active


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("dorp=0.1", "unknown key 'dorp'"),
        ("drop", "expected KEY=VALUE"),
        ("drop=1.5", "drop=1.5: P must be a probability in [0, 1]"),
        ("drop=-0.1", "P must be a probability"),
        ("drop=abc", "drop=abc: P is not a number"),
        ("delay=0.1:abc", "delay=0.1:abc: MS is not a number"),  # the whole value (a trial)
        ("burst=0.1:x", "burst=0.1:x: LEN is not an integer"),
        ("drop=nan", "P must be finite"),
        ("drop=0.1,drop=0.2", "drop given twice"),
        ("burst=0.1", "expected burst=P:LEN"),
        ("burst=0.1:0", "LEN must be an integer >= 1"),
        ("burst=0.1:2.5", "LEN is not an integer"),
        ("delay=0.1:-3", "MS must be a finite number >= 0"),
        ("delay=0.1", "expected delay=P:MS"),
        ("flip=0.1:65", "BITS must be an integer in [1, 64]"),
        ("flip=0.1:1:2", "expected flip=P[:BITS]"),
        ("babble=-1", "RATE must be a finite number >= 0"),
        ("babble=inf", "RATE must be finite"),
        ("busoff=2", "expected busoff=T:DUR"),
        ("busoff=-1:2", "T must be a finite number >= 0"),
        ("busoff=3:0", "busoff=3:0: DUR must be > 0 s"),
        ("babble=100:0x050:2:0", "babble=100:0x050:2:0: DUR must be > 0 s"),
        ("seed=x", "N is not an integer"),
        ("drop=0.6,dup=0.5", "> 1 (a frame suffers at most one of them)"),
        (",,,", "an empty item"),
        ("drop=0.1,", "an empty item"),
        ("drop=0.1,,seed=2", "an empty item"),
    ],
)
def test_spec_refuses_bad_text_with_one_line(text: str, expected: str) -> None:
    with pytest.raises(ConfigurationError) as info:
        FaultSpec.parse(text)
    message = str(info.value)
    assert expected in message
    assert "\n" not in message
    assert message.startswith("faults: ")


def test_spec_validates_programmatic_construction() -> None:
    with pytest.raises(ConfigurationError, match="flip=0: BITS"):
        FaultSpec(flip=0.1, flip_bits=0)
    with pytest.raises(ConfigurationError, match="drop=True"):
        FaultSpec(drop=True)  # a bool is a float to mypy: the spec itself must refuse it


# --- ErrorCounters -----------------------------------------------------------------------------
def test_error_counters_follow_iso_11898_fault_confinement() -> None:
    c = ErrorCounters()
    states = []
    for _ in range(32):
        c.transmit_error()
        states.append((c.tec, c.error_warning, c.bus_state))
    assert states[10] == (88, False, can.BusState.ACTIVE)
    assert states[11] == (96, True, can.BusState.ACTIVE)  # error warning
    assert states[15] == (128, True, can.BusState.PASSIVE)  # error passive
    assert states[30] == (248, True, can.BusState.PASSIVE)
    assert states[31] == (256, True, can.BusState.ERROR)  # TEC > 255: bus-off
    c.transmit_success()
    c.transmit_error()
    assert (c.tec, c.bus_off) == (256, True)  # frozen while bus-off
    c.recover()
    assert (c.tec, c.rec, c.bus_state) == (0, 0, can.BusState.ACTIVE)
    for _ in range(130):
        c.receive_error()
    assert (c.rec, c.bus_state) == (130, can.BusState.PASSIVE)
    c.receive_success()
    assert (c.rec, c.bus_state) == (127, can.BusState.ACTIVE)
    c.receive_success()
    assert c.rec == 126


# --- FaultInjectingBus on virtual buses --------------------------------------------------------
def _numbered(i: int, t_s: float, can_id: int = 0x123) -> can.Message:
    return can.Message(
        timestamp=t_s, arbitration_id=can_id, is_extended_id=False, data=i.to_bytes(8, "little")
    )


def _key(msg: can.Message | None) -> tuple[object, ...] | None:
    """What a receiver can tell of a frame."""
    if msg is None:
        return None
    flags = (msg.is_extended_id, msg.is_remote_frame, msg.is_error_frame)
    return (msg.timestamp, msg.arbitration_id, *flags, msg.dlc, bytes(msg.data))


def _send_all(
    spec: FaultSpec, n: int, period_s: float = 0.01
) -> tuple[FaultInjectingBus, list[can.Message]]:
    """Send frames 0..n-1 (numbered in their payload) through ``spec``; what a receiver got."""
    channel = unique_channel()
    rx = open_virtual(channel)
    bus = FaultInjectingBus(open_virtual(channel), spec)
    try:
        for i in range(n):
            bus.send(_numbered(i, i * period_s))
        got = []
        while (msg := rx.recv(0)) is not None:
            got.append(msg)
    finally:
        bus.shutdown()
        rx.shutdown()
    return bus, got


def test_no_faults_pass_every_frame_unchanged_both_ways() -> None:
    channel = unique_channel()
    peer = open_virtual(channel)
    with FaultInjectingBus(open_virtual(channel), FaultSpec()) as bus:
        sent = [_numbered(i, i * 0.01) for i in range(100)]
        for msg in sent:
            bus.send(msg)
            peer.send(_numbered(1000 + msg.data[0], msg.timestamp))
        got = [peer.recv(0) for _ in sent]
        back = [bus.recv(0) for _ in sent]
        assert bus.recv(0) is None
        assert [_key(g) for g in got] == [_key(m) for m in sent]
        assert [int.from_bytes(b.data, "little") for b in back if b] == [
            1000 + i for i in range(100)
        ]
        assert bus.injected == dict.fromkeys(FAULT_KINDS, 0)
        assert bus.state is can.BusState.ACTIVE
    peer.shutdown()


def test_drop_dup_and_flip_are_counted_and_logged(caplog: pytest.LogCaptureFixture) -> None:
    n = 20_000
    spec = FaultSpec(drop=0.05, dup=0.03, flip=0.02, flip_bits=3, seed=11)
    with caplog.at_level(logging.INFO, logger="odocan.faults"):
        bus, got = _send_all(spec, n)
    inj = bus.injected
    print(f"\n{n} frames: {inj['drop']} dropped, {inj['dup']} duplicated, {inj['flip']} flipped")
    assert len(got) == n - inj["drop"] + inj["dup"]
    for kind, p in (("drop", 0.05), ("dup", 0.03), ("flip", 0.02)):
        assert abs(inj[kind] - p * n) < 6 * (p * n) ** 0.5  # within 6 sigma of its probability
    seen: dict[int, int] = {}
    flipped = 0
    for msg in got:
        assert msg.arbitration_id == 0x123  # never the ID
        value = int.from_bytes(msg.data, "little")
        if value >= n:  # a number this sender never sent: corrupted
            flipped += 1
            continue
        seen[value] = seen.get(value, 0) + 1
    assert sum(1 for c in seen.values() if c == 2) >= inj["dup"] - inj["flip"]
    assert flipped <= inj["flip"]
    records = [r for r in caplog.records if r.name == "odocan.faults"]
    assert len(records) == sum(inj.values())
    assert all(r.levelno == logging.INFO and "\n" not in r.getMessage() for r in records)


def test_flip_inverts_exactly_bits_of_the_payload_and_leaves_the_sender_message_alone() -> None:
    channel = unique_channel()
    rx = open_virtual(channel)
    with FaultInjectingBus(open_virtual(channel), FaultSpec(flip=1.0, flip_bits=5)) as bus:
        for i in range(200):
            msg = _numbered(i, i * 0.01, can_id=0x100 + i)
            before = bytes(msg.data)
            bus.send(msg)
            assert bytes(msg.data) == before
            got = rx.recv(0)
            assert got is not None
            assert got.arbitration_id == 0x100 + i
            assert got.dlc == 8
            diff = int.from_bytes(got.data, "little") ^ int.from_bytes(before, "little")
            assert diff.bit_count() == 5
        assert bus.injected["flip"] == 200
    rx.shutdown()


def test_a_burst_loses_len_frames_in_a_row() -> None:
    bus, got = _send_all(FaultSpec(burst=0.01, burst_len=7, seed=5), 20_000)
    numbers = sorted(int.from_bytes(m.data, "little") for m in got)
    missing = sorted(set(range(20_000)) - set(numbers))
    runs = [len(list(g)) for _, g in itertools.groupby(enumerate(missing), lambda t: t[1] - t[0])]
    assert runs
    assert all(r % 7 == 0 for r in runs)  # back-to-back bursts make multiples of 7
    assert bus.injected["burst"] == len(missing)


def test_delay_holds_a_frame_and_lets_later_ones_overtake_it() -> None:
    channel = unique_channel()
    rx = open_virtual(channel)
    with FaultInjectingBus(open_virtual(channel), FaultSpec(delay=0.1, delay_ms=25, seed=2)) as bus:
        for i in range(2000):
            bus.send(_numbered(i, i * 0.01))
        bus.poll(2000 * 0.01)
        assert bus.held == 0
        order = []
        while (msg := rx.recv(0)) is not None:
            order.append((int.from_bytes(msg.data, "little"), msg.timestamp))
    rx.shutdown()
    numbers = [i for i, _ in order]
    assert sorted(numbers) == list(range(2000))  # nothing lost
    late = [(pos, i, t) for pos, (i, t) in enumerate(order) if t > i * 0.01 + 1e-9]
    assert len(late) == bus.injected["delay"] > 100
    for _, i, t in late:
        assert t == pytest.approx(i * 0.01 + 0.025)  # released 25 ms after it was sent
    prefix_max = list(itertools.accumulate(numbers, max))
    overtaken = sum(1 for pos, i, _ in late if pos > 0 and prefix_max[pos - 1] > i)
    assert overtaken == len(late)  # a frame sent after each delayed one arrives before it
    stamps = [t for _, t in order]
    assert stamps == sorted(stamps)


def test_same_seed_same_faults_other_seed_other_faults() -> None:
    spec = FaultSpec.parse("drop=0.05,dup=0.05,flip=0.05,delay=0.05:25,babble=30,seed=9")

    def frames(s: FaultSpec) -> list[tuple[float, int, bool, bool, bytes]]:
        return [
            (m.timestamp, m.arbitration_id, m.is_error_frame, m.is_remote_frame, bytes(m.data))
            for m in _send_all(s, 3000)[1]
        ]

    first = frames(spec)
    assert frames(spec) == first
    assert frames(FaultSpec.parse(str(spec).replace("seed=9", "seed=10"))) != first


def test_babble_is_random_frames_at_its_rate() -> None:
    bus, got = _send_all(FaultSpec(babble=500.0, seed=4), 1000)  # 10 s of sender time
    babble = [m for m in got if m.arbitration_id != 0x123 or m.is_extended_id or m.dlc != 8]
    count = bus.injected["babble"]
    print(f"\nbabble: {count} frames in 10 s at 500/s")
    assert abs(count - 5000) < 6 * 5000**0.5
    assert len(babble) >= count - 10  # a babble frame may look like ours
    assert any(m.is_error_frame for m in babble)
    assert any(m.is_remote_frame for m in babble)
    assert any(m.is_extended_id and m.arbitration_id > 0x7FF for m in babble)
    assert {m.dlc for m in babble} == set(range(9))
    stamps = [m.timestamp for m in got]
    assert stamps == sorted(stamps)
    assert stamps[-1] <= 9.99


def test_bus_off_refuses_sends_then_recovers_after_128_x_11_recessive_bits(
    caplog: pytest.LogCaptureFixture,
) -> None:
    spec = FaultSpec(busoff=BusOff(1.0, 0.5), delay=0.0, seed=1)
    channel = unique_channel()
    rx = open_virtual(channel)
    bitrate = 250_000
    recovered_at = 1.0 + 0.5 + 128 * 11 / bitrate  # 1.505632 s
    states, refused = [], 0
    with (
        caplog.at_level(logging.INFO, logger="odocan.faults"),
        FaultInjectingBus(open_virtual(channel), spec, bitrate=bitrate) as bus,
    ):
        for i in range(400):
            t = i * 0.005
            try:
                bus.send(_numbered(i, t))
            except can.CanOperationError:
                refused += 1
                assert 1.0 <= t < recovered_at
            states.append((t, bus.state, bus.tec))
    rx_count = sum(1 for _ in iter(lambda: rx.recv(0), None))
    rx.shutdown()
    assert all(s is can.BusState.ACTIVE and tec == 0 for t, s, tec in states if t < 1.0)
    assert all(s is can.BusState.ERROR and tec > 255 for t, s, tec in states if 1.0 <= t < 1.5)
    assert all(s is can.BusState.ACTIVE and tec == 0 for t, s, tec in states if t >= 1.51)
    assert refused == bus.injected["refused"] == 102  # t = 1.000 .. 1.505 s
    assert rx_count == 400 - refused
    assert bus.injected["busoff"] == 1
    log = caplog.text
    assert "TEC 96, error warning" in log
    assert "TEC 128, error passive" in log
    assert "TEC 256 > 255: bus-off" in log
    assert "recovered" in log


def test_wrapper_filters_shutdown_and_flush() -> None:
    channel = unique_channel()
    peer = open_virtual(channel)
    inner = open_virtual(channel)
    bus = FaultInjectingBus(
        inner,
        FaultSpec(delay=1.0, delay_ms=100),
        can_filters=[{"can_id": 0x100, "can_mask": 0x7FF, "extended": False}],
    )
    assert "faults(delay=1:100,seed=0) on Virtual bus channel" in bus.channel_info
    peer.send(_numbered(1, 0.0, can_id=0x101))
    peer.send(_numbered(2, 0.0, can_id=0x100))
    got = bus.recv(0.1)
    assert got is not None
    assert got.arbitration_id == 0x100
    bus.send(_numbered(3, 0.0))
    assert bus.held == 1
    bus.flush_tx_buffer()
    assert bus.held == 0
    bus.shutdown()
    bus.shutdown()  # twice is fine
    with pytest.raises(can.CanOperationError):
        inner.send(_numbered(4, 0.0))  # the wrapped bus was shut down too
    peer.shutdown()


# --- E2E against corruption --------------------------------------------------------------------
def _receiver(frame_id: int) -> E2EReceiver:
    """The firmware's Profile 2 check with the message's DBC data IDs (a fresh sequence)."""
    return E2EReceiver(dbc_data_ids(frame_id))


def _accepted(rx: E2EReceiver, word: int) -> bool:
    rx.reset()
    return rx.check(word.to_bytes(8, "little")) is not E2EStatus.ERROR


def test_catalogue_covers_every_message_and_page_of_the_dbc() -> None:
    types = dbc_frame_types()
    assert {name for name, _ in types} == {m.name for m in database().messages}
    assert ("ODOM_CONFIG", 15) in types
    assert ("ODOM_STATUS", 4) in types  # APPLY, a late page
    for frame_id, ids in hf.DATA_IDS_BY_FRAME_ID.items():
        assert dbc_data_ids(frame_id) == ids  # the firmware's lists are the DBC's


def test_every_single_bit_flip_of_every_frame_type_is_detected() -> None:
    checked = 0
    for counter in range(16):
        for key, (frame_id, data) in protected_frames(counter).items():
            rx = _receiver(frame_id)
            word = int.from_bytes(data, "little")
            assert _accepted(rx, word), key  # the clean frame passes
            for bit in range(64):  # byte 0 (the CRC itself) and the counter bits included
                assert not _accepted(rx, word ^ (1 << bit)), (key, counter, bit)
                checked += 1
    print(f"\nsingle-bit flips: {checked} of {checked} detected (100%)")


def test_every_double_bit_flip_of_every_frame_type_is_detected() -> None:
    checked = 0
    for i, (key, (frame_id, data)) in enumerate(protected_frames(0).items()):
        counter = i % 16
        frame_id, data = protected_frames(counter)[key]
        rx = _receiver(frame_id)
        word = int.from_bytes(data, "little")
        for a, b in itertools.combinations(range(64), 2):
            assert not _accepted(rx, word ^ (1 << a) ^ (1 << b)), (key, a, b)
            checked += 1
    print(f"\ndouble-bit flips: {checked} of {checked} detected (100%)")


def test_undetected_triple_bit_flips_all_flip_one_counter_bit() -> None:
    """CRC8H2F has Hamming distance 4 over a frame, but a counter bit also flips the data ID it
    selects, so a 3-bit error with one counter bit is a 4-bit error for the CRC."""
    frame_id, data = protected_frames(5)["WHEEL_ENCODERS", None]
    rx = _receiver(frame_id)
    word = int.from_bytes(data, "little")
    undetected = []
    total = 0
    for bits in itertools.combinations(range(64), 3):
        total += 1
        if _accepted(rx, word ^ sum(1 << b for b in bits)):
            undetected.append(bits)
    print(f"\ntriple-bit flips of WHEEL_ENCODERS: {len(undetected)} of {total} undetected")
    assert undetected  # the weakness is real ...
    assert all(sum(b in COUNTER_BITS for b in bits) == 1 for bits in undetected)  # ... and only so


def test_every_odd_weight_error_off_the_counter_is_detected() -> None:
    """0x2F (x^8 + x^5 + x^3 + x^2 + x + 1) has the factor x + 1: an error of odd weight that
    leaves the counter (and so the data ID) alone never passes. Hence even weights carry the
    misses, at about 2 x 2^-8 (bench/faults.py prints the rate per weight)."""
    rng = random.Random(3)
    catalogue = [f for c in range(16) for f in protected_frames(c).values()]
    receivers = {fid: _receiver(fid) for fid, _ in catalogue}
    not_counter = [b for b in range(64) if b not in COUNTER_BITS]
    for _ in range(20_000):
        frame_id, data = catalogue[rng.randrange(len(catalogue))]
        bits = rng.sample(not_counter, rng.randrange(1, 60, 2))
        error = sum(1 << b for b in bits)
        assert not _accepted(receivers[frame_id], int.from_bytes(data, "little") ^ error)


def test_random_multi_bit_corruption_passes_at_about_2_pow_minus_8() -> None:
    """Uniformly random error patterns of 2..64 bits on frames of every type and counter."""
    n = 100_000
    rng = random.Random(20240601)
    catalogue = [f for c in range(16) for f in protected_frames(c).values()]
    receivers = {fid: _receiver(fid) for fid, _ in catalogue}
    undetected = 0
    for _ in range(n):
        frame_id, data = catalogue[rng.randrange(len(catalogue))]
        error = 0
        while error.bit_count() < 2:  # a multi-bit error: any pattern of 2..64 bits
            error = rng.getrandbits(64)
        undetected += _accepted(receivers[frame_id], int.from_bytes(data, "little") ^ error)
    rate = undetected / n
    bound = binomial_upper_bound(undetected, n)
    print(
        f"\nrandom multi-bit corruption: {undetected} of {n} undetected = {rate:.3e} "
        f"({rate * 256:.3f} x 2^-8), 95% upper bound {bound:.3e} ({bound * 256:.3f} x 2^-8)"
    )
    assert undetected > 0
    # The claim is "about 2^-8 and at most 1.2 x 2^-8" (the CRC passes 2^-8 of random patterns,
    # the counter and window checks a little less): the 95 % upper bound must stay under it.
    assert bound <= 1.2 / 256


# --- the lockstep rig with faults --------------------------------------------------------------
def _encoder_faults(bus: FaultInjectingBus, kind: str) -> int:
    return bus.injected_by_id[kind, fr.WHEEL_ENCODERS_ID]


@pytest.mark.slow
def test_ten_minutes_of_drops_duplicates_and_flips_are_all_counted() -> None:
    spec = FaultSpec.parse("drop=0.01,dup=0.005,flip=0.001,seed=42")
    with FaultRig(sim_faults=spec, scenario=RandomScenario(42, duration_s=600.0), seed=42) as rig:
        audit = PoseAudit(rig.params, rig.integrator)
        states: set[int] = set()
        rig.observers += [audit, lambda k, frames: _collect_states(frames, states)]
        rig.run(600.0)
        bus = rig.sim_bus
        assert isinstance(bus, FaultInjectingBus)
        rx = rig.ecu.rx_encoders
        drops = _encoder_faults(bus, "drop")
        dups = _encoder_faults(bus, "dup")
        flips = _encoder_faults(bus, "flip")
        ex, ey, eh, n = audit.max_errors_lsb()
        print(
            f"\n10 min, {bus.offered} frames offered: WHEEL_ENCODERS {drops} dropped, {dups} "
            f"duplicated, {flips} flipped; firmware lost {rx.lost_frames}, repeated "
            f"{rx.count_repeated}, crc errors {rx.count_error}; pose vs float64 on the accepted "
            f"counts over {n} pose frames: X {ex:.3f}, Y {ey:.3f}, HEADING {eh:.3f} LSB"
        )
        assert min(drops, dups, flips) > 0
        assert rx.count_error == flips  # single-bit flips: every one fails the CRC
        assert rx.count_repeated == dups
        assert rx.lost_frames == drops + flips  # a flipped frame is lost to the sequence too
        assert rx.count_wrongsequence == 0
        assert audit.rx.lost_frames == rx.lost_frames  # the audit saw what the firmware saw
        assert max(ex, ey, eh) < 1.0
        assert rig.ecu.state is State.OK
        assert states == {State.OK}
        assert not rig.ecu.errors.has(ErrorFlag.ENCODER_TIMEOUT)


def _collect_states(frames: list[can.Message], states: set[int]) -> None:
    for msg in frames:
        if msg.arbitration_id == fr.ODOM_STATUS_ID:
            page = hf.unpack_odom_status(bytes(msg.data))
            if isinstance(page, hf.OdomStatusSummary):
                states.add(page.state)


def _final_pose(rig: FaultRig) -> tuple[int, int, int]:
    odo = rig.ecu.odometry
    return odo.x_q40_m, odo.y_q40_m, odo.heading_bam64


def _replayer(rig: FaultRig, ages: tuple[int, ...], every: int) -> tuple[list[int], can.BusABC]:
    """A node that records WHEEL_ENCODERS (one per period: duplicates skipped) and, every
    ``every`` ticks, replays the one ``age`` periods older than the newest (ages taken in turn),
    right after the genuine frame."""
    bus = open_virtual(rig.channel)
    history: list[can.Message] = []
    replayed = [0]

    def hook(k: int) -> None:
        fresh = [m for m in iter(lambda: bus.recv(0), None) if m.arbitration_id == 0x100]
        if fresh:
            history.append(fresh[0])
        if k % every == 1 and len(history) > max(ages):
            old = history[-1 - ages[replayed[0] % len(ages)]]
            bus.send(
                can.Message(
                    timestamp=k * 0.01,
                    arbitration_id=old.arbitration_id,
                    is_extended_id=False,
                    data=old.data,
                )
            )
            replayed[0] += 1

    rig.before_board.append(hook)
    return replayed, bus


def _run_with_replays(
    ages: tuple[int, ...], dup: float
) -> tuple[tuple[int, int, int], int, FaultRig]:
    spec = FaultSpec(dup=dup, seed=8)
    with FaultRig(sim_faults=spec, seed=8) as rig:
        replayed, bus = _replayer(rig, ages, every=5) if ages else ([0], None)
        rig.run(40.0)
        if bus is not None:
            bus.shutdown()
        return _final_pose(rig), replayed[0], rig


@functools.cache
def _clean_pose(dup: float) -> tuple[int, int, int]:
    """The final pose of the replay tests' run without replays (``dup``: duplicates only)."""
    with FaultRig(sim_faults=FaultSpec(dup=dup, seed=8) if dup else None, seed=8) as clean:
        clean.run(40.0)
        return _final_pose(clean)


def test_duplicates_and_replays_leave_the_pose_bit_identical() -> None:
    expected = _clean_pose(0.0)
    # Replays 1..14, 16 and 32 periods old, after the genuine frame and among duplicates. The
    # firmware widens the encoder window once per tick, not per frame, so neither a duplicate nor
    # a replay widens it: a replay 13 or 14 old (delta +3/+2) is a WRONGSEQUENCE. 15: see below.
    ages = (*range(1, 15), 16, 32)
    pose, replayed, rig = _run_with_replays(ages, dup=0.05)
    rx = rig.ecu.rx_encoders
    dups = _encoder_faults(rig.sim_bus, "dup")  # type: ignore[arg-type]
    print(f"\n{dups} duplicates and {replayed} replays: pose {pose} (clean {expected})")
    assert dups > 100
    assert replayed > 600
    assert pose == expected
    assert rx.count_repeated + rx.count_wrongsequence == dups + replayed
    assert rx.lost_frames == 0


@pytest.mark.xfail(
    strict=True,
    reason="Profile 2 limit: a replay exactly one counter cycle old (15 periods) carries the next "
    "expected COUNTER, so no counter rule can tell it from fresh data",
)
def test_a_replay_one_counter_cycle_old_passes_profile_2() -> None:
    """A stale frame 15 periods old, sent right after the genuine one, has COUNTER = last + 1:
    Profile 2 accepts it; the counts jump back 15 periods and forth again, and the position (not
    the heading: an exact sum of counts) leaves the clean run's. Kept as a strict xfail so a
    future freshness mechanism (e.g. a wider counter) shows up as a pass."""
    expected = _clean_pose(0.0)
    pose, replayed, _ = _run_with_replays((15,), dup=0.0)
    assert replayed > 600
    assert pose == expected


def _receive_all(reader: can.BufferedReader, frames: list[can.Message]) -> None:
    for m in frames:
        reader.on_message_received(m)


def test_bus_off_of_the_motor_controller_degrades_the_firmware_and_latches_pose_uncertain() -> None:
    spec = FaultSpec.parse("busoff=3:0.5,seed=1")
    reader = can.BufferedReader()
    with FaultRig(sim_faults=spec, seed=1) as rig:
        rig.observers.append(lambda k, frames: _receive_all(reader, frames))
        bus = rig.sim_bus
        assert isinstance(bus, FaultInjectingBus)
        seen: list[tuple[float, can.BusState]] = []
        rig.observers.append(lambda k, frames: seen.append((k * 0.01, bus.state)))
        rig.run(6.0)
        refused = bus.injected["refused"]
    summaries = []
    db = database()
    while (msg := reader.get_message(0)) is not None:
        if msg.arbitration_id == fr.ODOM_STATUS_ID:
            signals = decode(db, msg.arbitration_id, msg.data, decode_choices=True)
            if signals["PAGE"] == "SUMMARY":
                state, mask = str(signals["STATE"]), int(number(signals["ERROR_MASK"]))
                summaries.append((msg.timestamp, state, mask))
    states = [s for _, s, _ in summaries]
    first_degraded = next(t for t, s, _ in summaries if s == "DEGRADED")
    print(
        f"\nbus-off at 3.0 s for 0.5 s (+2.8 ms recovery): ODOM_STATUS DEGRADED from "
        f"{first_degraded:.3f} s; {refused} frames refused"
    )
    assert states[0] in ("INIT", "OK")
    assert "DEGRADED" in states
    assert 3.0 < first_degraded < 3.5
    assert summaries[-1][2] & ErrorFlag.ENCODER_TIMEOUT
    # The first frame after it spans the 0.5 s, a path the firmware cannot know: its worst case
    # passes the uncertainty's tolerance, DEGRADED POSE_UNCERTAIN until a set-pose, not OK.
    assert states[-1] == "DEGRADED"
    assert summaries[-1][2] & ErrorFlag.POSE_UNCERTAIN
    assert all(s is can.BusState.ERROR for t, s in seen if 3.0 <= t < 3.5)
    assert all(s is can.BusState.ACTIVE for t, s in seen if t < 3.0 or t >= 3.51)
    assert bus.injected["busoff"] == 1
    assert bus.injected["refused"] > 50
