"""SecOC figures (issue #18): forgery and replay acceptance, AES-CMAC cost, bus load, latency.

Prints; asserts nothing. Run: ``.venv/bin/python bench/secoc.py [--tries N] [--bits 32,24,16,8]
[--replays N] [--cost N] [--c-calls N]``. Defaults: 10^6 forged commands at each truncation (32
bits is the profile; 24 the issue's example; 16 and 8 give counts large enough to compare with
2^-N), 10^4 recorded commands replayed (before and after a reboot), 2000 timed verifications,
10^6 calls of the C authenticator (bench/secoc_authenticator.c, compiled with ``cc`` when there
is one); about 2.5 minutes on one core of the CI machine.

* **Forgery**: a node without the key sends random commands of the three secured messages, each
  at the right freshness (public: ODOM_FRESHNESS, the last FRESHNESS on the bus) with a random
  authenticator; every try goes through the firmware's ``SecocReceiver.verify`` (one AES-128 each).
* **Bus**: the exact length in bits of every frame sent (CAN 2.0A: SOF to EOF with the real
  stuff bits, plus the 3-bit intermission), at 500 kbit/s; the CAN FD alternative from the
  ISO 11898-1:2015 frame format (worst-case stuffing), see docs/secoc.md.
"""

from __future__ import annotations

import argparse
import math
import random
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from odocan.firmware import secoc as fw
from odocan.firmware.cmac import cmac_key
from odocan.firmware.e2e import E2EReceiver
from odocan.host.protocol.secoc import SecocSigner
from tests.fault_rig import binomial_upper_bound
from tests.host_frames import p02_protect

KEY = bytes.fromhex("2b7e151628aed2a6abf7158809cf4f3c")
BITRATE = 500_000  # bit/s, the odocan bus
TICK_US = 10_000
INTERMISSION_BITS = 3
SEQUENCES = {"set_pose": 4, "config": 7, "nav_goal": 4}  # frames per command (host.protocol)


class MemoryNvm:
    """A simulated NVM cell."""

    def __init__(self) -> None:
        self.epoch = 0

    def read_epoch(self) -> int:
        return self.epoch

    def write_epoch(self, epoch: int) -> bool:
        self.epoch = epoch
        return True


def random_command(rng: random.Random) -> tuple[int, bytes]:
    can_id = rng.choice(fw.SECURED_IDS)
    frame = bytearray(rng.randbytes(8))
    p02_protect(frame, rng.randrange(16), tuple(range(16)))
    return can_id, bytes(frame)


# --- forgery ---------------------------------------------------------------------------------
def forge(tries: int, mac_bits: int, seed: int) -> tuple[int, float]:
    """Random authenticators at the right freshness: (accepted, seconds)."""
    rng = random.Random(seed)
    receiver = fw.SecocReceiver(KEY, MemoryNvm(), mac_bits=mac_bits)
    commands = [random_command(rng) for _ in range(4096)]
    start = time.perf_counter()
    accepted = 0
    for i in range(tries):
        can_id, pdu = commands[i & 4095]
        freshness = (receiver.last_fv + 1) & fw.FRESHNESS_TX_MASK
        status = receiver.verify(can_id, pdu, freshness, rng.getrandbits(mac_bits))
        accepted += status is fw.AuthStatus.OK
    return accepted, time.perf_counter() - start


def print_forgery(tries: int, bits: list[int]) -> None:
    print(f"forged commands ({tries} tries per truncation, random authenticator, right FV)")
    print(
        f"  {'bits':>4} {'accepted':>9} {'rate':>10} {'2^-N':>10} {'expected':>9} "
        f"{'95% upper':>10} {'z':>6} {'us/try':>7}"
    )
    for n in bits:
        accepted, seconds = forge(tries, n, seed=n)
        p = 2.0**-n
        sigma = math.sqrt(tries * p * (1 - p))
        z = (accepted - tries * p) / sigma
        upper = binomial_upper_bound(accepted, tries)
        print(
            f"  {n:>4} {accepted:>9} {accepted / tries:>10.3e} {p:>10.3e} {tries * p:>9.3g} "
            f"{upper:>10.3e} {z:>6.2f} {seconds / tries * 1e6:>7.1f}"
        )


# --- replay ----------------------------------------------------------------------------------
def print_replay(count: int) -> None:
    rng = random.Random(18)
    nvm = MemoryNvm()
    receiver = fw.SecocReceiver(KEY, nvm)
    signer = SecocSigner(KEY)
    signer.on_freshness(receiver.freshness_frame(0, fw.FreshnessCause.BOOT))
    recorded = []
    for _ in range(count):
        can_id, pdu = random_command(rng)
        auth = fw.unpack_odom_auth(signer.sign(can_id, pdu))
        receiver.verify(can_id, pdu, auth.freshness, auth.authenticator)
        recorded.append((can_id, pdu, auth))
    genuine = receiver.count_ok

    def replay() -> dict[str, int]:
        counts: dict[str, int] = {}
        for can_id, pdu, auth in recorded:
            status = receiver.verify(can_id, pdu, auth.freshness, auth.authenticator)
            counts[status.name] = counts.get(status.name, 0) + 1
        return counts

    print(f"replayed genuine commands ({count} recorded, {genuine} of them accepted once)")
    print(f"  replayed at once:        {replay()}")
    receiver.boot()
    print(f"  replayed after a reboot: {replay()}  (EPOCH now {receiver.epoch})")


# --- cost ------------------------------------------------------------------------------------
def per_call_us(fn: Callable[[], object], calls: int) -> float:
    """Median of 5 runs of ``calls`` calls, in microseconds per call."""
    runs = []
    for _ in range(5):
        start = time.perf_counter()
        for _ in range(calls):
            fn()
        runs.append((time.perf_counter() - start) / calls * 1e6)
    return statistics.median(runs)


def print_cost(calls: int) -> None:
    rng = random.Random(7)
    key = cmac_key(KEY)
    can_id, pdu = random_command(rng)
    nvm = MemoryNvm()
    receiver = fw.SecocReceiver(KEY, nvm)
    signer = SecocSigner(KEY)
    signer.on_freshness(receiver.freshness_frame(0, fw.FreshnessCause.BOOT))
    pairs = iter([fw.unpack_odom_auth(signer.sign(can_id, pdu)) for _ in range(5 * calls)])

    def verify_next() -> object:
        """A genuine command each call: the freshness check passes, the AES block runs."""
        auth = next(pairs)
        return receiver.verify(can_id, pdu, auth.freshness, auth.authenticator)

    e2e = E2EReceiver(tuple(range(16)), max_delta_counter_init=15)
    print(f"cost per command in CPython {sys.version.split()[0]} (median of 5 x {calls})")
    print(
        f"  firmware AES-CMAC authenticator (1 AES block): "
        f"{per_call_us(lambda: fw.authenticator(key, can_id, pdu, 12345), calls):6.1f} us"
    )
    verify_us = per_call_us(verify_next, calls)
    print(
        f"  firmware SecocReceiver.verify, genuine:        {verify_us:6.1f} us "
        f"({receiver.count_ok} of {5 * calls} timed calls accepted)"
    )
    print(
        f"  firmware key provisioning (expand + K1, K2):   "
        f"{per_call_us(lambda: cmac_key(KEY), calls):6.1f} us (once per key)"
    )
    print(
        f"  firmware E2E Profile 2 check, for scale:       "
        f"{per_call_us(lambda: e2e.check(pdu), calls):6.1f} us"
    )
    print(
        f"  host SecocSigner.sign (cryptography + cantools): "
        f"{per_call_us(lambda: signer.sign(can_id, pdu), calls):6.1f} us"
    )


# --- the same authenticator in C ---------------------------------------------------------------
C_SOURCE = Path(__file__).resolve().parent / "secoc_authenticator.c"
C_VECTOR = (0x300, bytes.fromhex("3600393000000000"), 0x000010000001)  # docs/secoc.md, row 1


def print_c_cost(calls: int) -> None:
    """Compile bench/secoc_authenticator.c, check it bit for bit, time it (this host's CPU)."""
    compiler = shutil.which("cc")
    if compiler is None:
        print("C: no cc on this machine, skipped")
        return
    with tempfile.TemporaryDirectory() as tmp:
        exe = Path(tmp) / "authenticator"
        subprocess.run([compiler, "-O2", "-std=c99", "-o", str(exe), str(C_SOURCE)], check=True)
        out = subprocess.run([str(exe), str(calls)], capture_output=True, text=True, check=True)
    vector_line, timing_line = out.stdout.split("\n")[:2]
    expected = fw.authenticator(cmac_key(KEY), *C_VECTOR)
    same = "matches" if int(vector_line, 16) == expected else "DIFFERS from"
    print(
        f"C (cc -O2, this machine's CPU, not an MCU): {float(timing_line.split()[1]):.0f} ns "
        f"per authenticator over {calls} calls; its vector {same} the Python firmware's"
    )


# --- bus -------------------------------------------------------------------------------------
def _crc15(bits: list[int]) -> int:
    """CAN CRC-15 (polynomial 0x4599) over ``bits``."""
    crc = 0
    for bit in bits:
        top = ((crc >> 14) & 1) ^ bit
        crc = (crc << 1) & 0x7FFF
        if top:
            crc ^= 0x4599
    return crc


def _bits(value: int, width: int) -> list[int]:
    return [(value >> (width - 1 - i)) & 1 for i in range(width)]


def classic_frame_bits(can_id: int, data: bytes) -> int:
    """Bits on the wire of a CAN 2.0A data frame, stuff bits counted, plus the intermission."""
    head = [0, *_bits(can_id, 11), 0, 0, 0, *_bits(len(data), 4)]
    for byte in data:
        head += _bits(byte, 8)
    stuffed = head + _bits(_crc15(head), 15)
    stuff_bits, run, last = 0, 0, -1
    for bit in stuffed:
        if bit == last:
            run += 1
        else:
            run, last = 1, bit
        if run == 5:
            stuff_bits += 1
            last, run = 1 - bit, 1  # the stuff bit starts the next run
    return len(stuffed) + stuff_bits + 10 + INTERMISSION_BITS  # CRC del, ACK, ACK del, EOF


def fd_frame_us(payload: int, nominal: int, data_rate: int) -> float:
    """Worst-case duration of a CAN FD base-format frame (<= 16 bytes: CRC-17), microseconds.

    Arbitration phase at ``nominal``: SOF, 11-bit ID, RRS, IDE, FDF, res, BRS (17 bits, <= 3 stuff
    bits); data phase at ``data_rate``: ESI, DLC (4), the payload, stuff count (4), CRC-17 with
    its 6 fixed stuff bits, the CRC delimiter, dynamic stuff bits <= (5 + 8 * payload) / 4; then
    ACK, ACK delimiter, EOF (7) and the intermission (3) at ``nominal``.
    """
    arbitration = 17 + 3
    data_bits = 1 + 4 + 8 * payload
    data_phase = data_bits + data_bits // 4 + 4 + 17 + 6 + 1
    tail = 1 + 1 + 7 + INTERMISSION_BITS
    return (arbitration + tail) * 1e6 / nominal + data_phase * 1e6 / data_rate


def print_bus(samples: int) -> None:
    rng = random.Random(9)
    receiver = fw.SecocReceiver(KEY, MemoryNvm())
    signer = SecocSigner(KEY)
    signer.on_freshness(receiver.freshness_frame(0, fw.FreshnessCause.BOOT))
    command_bits, auth_bits = [], []
    for _ in range(samples):
        can_id, pdu = random_command(rng)
        command_bits.append(classic_frame_bits(can_id, pdu))
        auth_bits.append(classic_frame_bits(fw.ODOM_AUTH_ID, signer.sign(can_id, pdu)))
    bit_us = 1e6 / BITRATE
    mean_auth = statistics.fmean(auth_bits)
    print(f"bus at {BITRATE // 1000} kbit/s ({samples} random commands; exact stuff bits)")
    print(
        f"  command frame today:   mean {statistics.fmean(command_bits):6.1f} bits, "
        f"max {max(command_bits)} bits (worst case 135 + 3)"
    )
    print(
        f"  ODOM_AUTH added:       mean {mean_auth:6.1f} bits = {mean_auth * bit_us:6.1f} us, "
        f"max {max(auth_bits)} bits = {max(auth_bits) * bit_us:6.1f} us"
    )
    for name, frames in SEQUENCES.items():
        print(
            f"  {name:<9} ({frames} frames): +{frames * mean_auth:5.0f} bits "
            f"= +{frames * mean_auth * bit_us / 1000:5.2f} ms of bus time per command"
        )
    fresh = classic_frame_bits(
        fw.ODOM_FRESHNESS_ID, receiver.freshness_frame(0, fw.FreshnessCause.PERIODIC)
    )
    print(f"  ODOM_FRESHNESS 1 Hz:   {fresh} bits/s = {fresh / BITRATE * 100:.4f} % of the bus")
    tick_share = mean_auth * bit_us / TICK_US
    print(
        f"  added latency (host sends the pair back to back): one frame, "
        f"{mean_auth * bit_us / 1000:.2f} ms, plus one 10 ms tick when the tick boundary falls "
        f"between the two frames (p = {tick_share:.3f}): mean "
        f"{(mean_auth * bit_us + tick_share * TICK_US) / 1000:.2f} ms, worst "
        f"{(max(auth_bits) * bit_us + TICK_US) / 1000:.2f} ms, + the verify time"
    )
    classic_us = 138 * bit_us
    for label, data_rate in (("no BRS", BITRATE), ("BRS 2 Mbit/s", 2_000_000)):
        fd_us = fd_frame_us(16, BITRATE, data_rate)
        print(
            f"  CAN FD alternative, 16-byte frame, {label:<12}: {fd_us:6.1f} us worst case "
            f""
            f"({fd_us - classic_us:+6.1f} us per command frame vs its classic worst "
            f"{classic_us:.0f} us)"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--tries", type=int, default=1_000_000)
    parser.add_argument("--bits", default="32,24,16,8")
    parser.add_argument("--replays", type=int, default=10_000)
    parser.add_argument("--cost", type=int, default=2000)
    parser.add_argument("--c-calls", type=int, default=1_000_000)
    args = parser.parse_args()
    print_cost(args.cost)
    print_c_cost(args.c_calls)
    print_bus(10_000)
    print_replay(args.replays)
    print_forgery(args.tries, [int(b) for b in args.bits.split(",")])


if __name__ == "__main__":
    main()
