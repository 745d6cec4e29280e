"""Fault figures (issue #6): the E2E check against corruption, fuzzing, the injector, the rig.

Prints; asserts nothing. Run: ``.venv/bin/python bench/faults.py [--corrupt N] [--fuzz N]
[--board-fuzz N] [--minutes M]``. Defaults: 10^6 corrupted frames, 10^6 fuzzed frames into the
ECU and 10^6 through a virtual bus into the board, 10 simulated minutes of faults in the rig
(about 3 minutes in all).
"""

from __future__ import annotations

import argparse
import random
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import can

from odocan.firmware import frames as fr
from odocan.firmware.e2e import E2EReceiver, E2EStatus
from odocan.sim.board import FirmwareBoard
from odocan.sim.clock import LockstepClock
from odocan.sim.faults import FaultInjectingBus, FaultSpec
from odocan.sim.scenarios import RandomScenario
from tests import host_frames as hf
from tests.fault_rig import (
    FaultRig,
    PoseAudit,
    binomial_upper_bound,
    burst_sizes,
    dbc_data_ids,
    fuzz_ecu,
    open_virtual,
    protected_frames,
    random_message,
    unique_channel,
)
from tests.odo_helpers import params

TWO_POW_MINUS_8 = 1 / 256
_ALL_FAULTS = "drop=0.01,dup=0.01,flip=0.01,delay=0.01:15,babble=100"


def _catalogue() -> list[tuple[E2EReceiver, int]]:
    """(receiver, frame as a u64) for every DBC frame type at every counter value."""
    receivers: dict[int, E2EReceiver] = {}
    out = []
    for counter in range(16):
        for frame_id, data in protected_frames(counter).values():
            rx = receivers.setdefault(frame_id, E2EReceiver(dbc_data_ids(frame_id)))
            out.append((rx, int.from_bytes(data, "little")))
    return out


def _undetected(catalogue: list[tuple[E2EReceiver, int]], errors: list[int]) -> int:
    """How many of ``errors`` (XOR masks), each on a random frame, pass the CRC."""
    rng = random.Random(1)
    passed = 0
    for error in errors:
        rx, word = catalogue[rng.randrange(len(catalogue))]
        rx.reset()
        passed += rx.check((word ^ error).to_bytes(8, "little")) is not E2EStatus.ERROR
    return passed


def _report_rate(label: str, k: int, n: int) -> None:
    bound = binomial_upper_bound(k, n) if k < 20_000 else k / n
    print(
        f"  {label:<34} {k:>7} / {n:<8} = {k / n:.3e} ({k / n / TWO_POW_MINUS_8:.3f} x 2^-8), "
        f"95% upper {bound:.3e} ({bound / TWO_POW_MINUS_8:.3f} x 2^-8)"
    )


def bench_corruption(n: int) -> None:
    """Undetected rates of random multi-bit errors, and by error weight."""
    print("E2E Profile 2 (CRC8H2F + data ID) against corruption, frames of every DBC type:")
    catalogue = _catalogue()
    rng = random.Random(2024)
    start = time.perf_counter()
    errors = []
    while len(errors) < n:
        e = rng.getrandbits(64)
        if e.bit_count() >= 2:
            errors.append(e)
    _report_rate("random multi-bit (2..64 bits)", _undetected(catalogue, errors), n)
    per_weight = max(n // 10, 1000)
    for weight in (3, 4, 5, 8, 16):
        masks = [sum(1 << b for b in rng.sample(range(64), weight)) for _ in range(per_weight)]
        _report_rate(f"exactly {weight} bits", _undetected(catalogue, masks), per_weight)
    elapsed = time.perf_counter() - start
    print(f"  ({n + 5 * per_weight} checks in {elapsed:.1f} s)")


def bench_fuzz_ecu(n: int) -> None:
    """``n`` random frames into ``OdomEcu.isr_can_rx`` + ``tick``."""
    start = time.perf_counter()
    fuzz = fuzz_ecu(n, seed=6)
    elapsed = time.perf_counter() - start
    ecu = fuzz.ecu
    print(
        f"fuzz, OdomEcu.isr_can_rx + tick: {n} frames in {elapsed:.1f} s (tracemalloc on), no "
        f"exception; overflows {ecu.mailbox.overflows} (expected {fuzz.expected_overflows}), "
        f"filtered {ecu.frames_filtered}, rejected {ecu.frames_rejected}, "
        f"memory {fuzz.grown_bytes:+d} B after 10%"
    )


def bench_fuzz_board(n: int) -> None:
    """``n`` random messages (error, remote, extended frames too) through a virtual bus."""
    rng = random.Random(7)
    channel = unique_channel()
    sender = open_virtual(channel)
    board = FirmwareBoard(open_virtual(channel), params("rk2"), LockstepClock())
    start = time.perf_counter()
    t = 0.0
    for burst in burst_sizes(rng, n):
        for _ in range(burst):
            sender.send(random_message(rng, t))
        board.run_tick()
        t += 0.01
    elapsed = time.perf_counter() - start
    sender.shutdown()
    board.bus.shutdown()
    print(
        f"fuzz, virtual bus -> FirmwareBoard.service_rx: {n} messages in {elapsed:.1f} s, no "
        f"exception; {board.frames_dropped_by_filter} dropped by the acceptance filter, "
        f"{board.ecu.mailbox.overflows} mailbox overflows"
    )


def bench_injector(n: int) -> None:
    """Frames/s through a bare virtual bus and through a FaultInjectingBus around one."""
    for label, spec in (
        ("(warm-up)", None),
        ("bare virtual bus", None),
        ("faults, none active", FaultSpec()),
        ("drop,dup,flip,delay,babble", FaultSpec.parse(_ALL_FAULTS)),
    ):
        channel = unique_channel()
        rx = open_virtual(channel)
        raw = open_virtual(channel)
        bus = raw if spec is None else FaultInjectingBus(raw, spec)
        msgs = [
            can.Message(timestamp=i / 1000, arbitration_id=0x100, data=bytes(8)) for i in range(n)
        ]
        start = time.perf_counter()
        for msg in msgs:
            bus.send(msg)
        elapsed = time.perf_counter() - start
        received = 0
        while rx.recv(0) is not None:
            received += 1
        bus.shutdown()
        rx.shutdown()
        print(f"  send, {label:<28} {n / elapsed:>9.0f} frames/s ({received} received)")


def bench_rig(minutes: float) -> None:
    """The lockstep rig with 1% drops, 0.5% duplicates, 0.1% flips; then bus-off."""
    spec = FaultSpec.parse("drop=0.01,dup=0.005,flip=0.001,seed=42")
    seconds = minutes * 60.0
    start = time.perf_counter()
    with FaultRig(sim_faults=spec, scenario=RandomScenario(42, duration_s=seconds), seed=42) as rig:
        audit = PoseAudit(rig.params, rig.integrator)
        rig.observers.append(audit)
        rig.run(seconds)
        bus = rig.sim_bus
        assert isinstance(bus, FaultInjectingBus)
        rx = rig.ecu.rx_encoders
        inj = {k: bus.injected_by_id[k, fr.WHEEL_ENCODERS_ID] for k in ("drop", "dup", "flip")}
        ex, ey, eh, n = audit.max_errors_lsb()
        elapsed = time.perf_counter() - start
        print(
            f"rig, {minutes:g} min ({elapsed:.1f} s wall) with {spec}:\n"
            f"  WHEEL_ENCODERS injected: {inj['drop']} dropped, {inj['dup']} duplicated, "
            f"{inj['flip']} flipped\n"
            f"  firmware E2E: lost {rx.lost_frames}, repeated {rx.count_repeated}, crc errors "
            f"{rx.count_error}, wrong sequence {rx.count_wrongsequence}; state "
            f"{rig.ecu.state.name}\n"
            f"  pose vs float64 on the accepted counts, {n} pose frames: X {ex:.3f}, Y {ey:.3f}, "
            f"HEADING {eh:.3f} LSB"
        )
    _bench_busoff()


def _bench_busoff() -> None:
    reader = can.BufferedReader()
    with FaultRig(sim_faults=FaultSpec.parse("busoff=3:0.5,seed=1"), seed=1) as rig:
        rig.observers.append(lambda k, frames: [reader.on_message_received(m) for m in frames])
        rig.run(6.0)
        bus = rig.sim_bus
        assert isinstance(bus, FaultInjectingBus)
        refused = bus.injected["refused"]
    states = []
    while (msg := reader.get_message(0)) is not None:
        if msg.arbitration_id == fr.ODOM_STATUS_ID:
            page = hf.unpack_odom_status(bytes(msg.data))
            if isinstance(page, hf.OdomStatusSummary):
                states.append((round(msg.timestamp, 3), page.state))
    changes = [(t, s) for i, (t, s) in enumerate(states) if i == 0 or s != states[i - 1][1]]
    print(
        f"rig, bus-off of the sim's handle at 3 s for 0.5 s: {refused} frames refused; "
        f"ODOM_STATUS STATE changes (s, state): {changes}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--corrupt", type=int, default=1_000_000)
    parser.add_argument("--fuzz", type=int, default=1_000_000)
    parser.add_argument("--board-fuzz", type=int, default=1_000_000)
    parser.add_argument("--minutes", type=float, default=10.0)
    args = parser.parse_args()
    bench_corruption(args.corrupt)
    bench_fuzz_ecu(args.fuzz)
    bench_fuzz_board(args.board_fuzz)
    print("injector throughput:")
    bench_injector(20_000)
    bench_rig(args.minutes)


if __name__ == "__main__":
    main()
