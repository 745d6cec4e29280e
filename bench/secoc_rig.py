"""SecOC in the lockstep rig: the bus load and the command latency it adds (figures, no asserts).

Two identical closed-loop rigs (pmir, exact integrator), one firmware without a key and one
provisioned with it; the host sends one ODOM_SET_POSE command (X, Y, HEADING, APPLY) every
``--period`` simulated seconds, unsigned to the first, signed (an ODOM_AUTH after each frame) to
the second. Reported per rig: every frame on the bus over the run with its exact bits (stuff bits
counted, ``bench.secoc.classic_frame_bits``) at 500 kbit/s, and the latency of each command, from
the host's send of its first frame to the firmware's ODOM_ACK of APPLY (simulated bus time: the
rig's tick and TX latency, not CPU time: the rig delivers a tick's frames together, so the
0.23 ms of wire time per ODOM_AUTH frame computed by ``bench/secoc.py`` does not show here), and
the wall time per command (signing plus the rig's ticks until the ACK).

    python bench/secoc_rig.py [--seconds 60] [--period 1.0]
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections import Counter

import can

from bench.secoc import BITRATE, classic_frame_bits
from odocan.firmware import frames as fr
from odocan.firmware.errors import ErrorMask
from odocan.host.protocol.secoc import SecocSigner
from odocan.sim.board import TICK_S
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.robot import load
from tests import host_frames as hf

KEY = bytes(range(16))
FRESHNESS_ID = fr.ODOM_FRESHNESS_ID


class Tape(can.Listener):
    """Every frame the host hears, in order."""

    def __init__(self) -> None:
        self.frames: list[can.Message] = []

    def on_message_received(self, msg: can.Message) -> None:
        self.frames.append(msg)


def set_pose_frames(counter0: int, k: int) -> list[tuple[int, bytes]]:
    e = ErrorMask()
    fields = (
        (fr.SetPoseField.X, k),
        (fr.SetPoseField.Y, -k),
        (fr.SetPoseField.HEADING, k),
        (15, 0),
    )
    return [
        (fr.ODOM_SET_POSE_ID, hf.pack_odom_set_pose(counter0 + i, f, v, e))
        for i, (f, v) in enumerate(fields)
    ]


def drive(secured: bool, seconds: float, period_s: float) -> dict[str, object]:
    """One rig run; its frames, command latencies (s) and wall time per command (s)."""
    tape = Tape()
    config = RigConfig(
        load("pmir"),
        scenario=None,
        channel=f"bench_secoc_{secured}",
        secoc_key=KEY if secured else None,
    )
    signer = SecocSigner(KEY) if secured else None
    latencies: list[float] = []
    wall: list[float] = []
    with LockstepRig(config, [tape]) as rig:
        rig.run(0.5)
        commands = 0
        every = round(period_s / TICK_S)
        for k in range(round(seconds / TICK_S)):
            if k % every == 0:
                frames = set_pose_frames(4 * commands, k)
                start = time.perf_counter()
                if signer is not None:
                    if signer.next_fv is None:
                        fresh = [m for m in tape.frames if m.arbitration_id == FRESHNESS_ID]
                        signer.on_freshness(bytes(fresh[-1].data))
                    frames = signer.secure(frames)
                sent_s = rig.clock.now_s()
                for can_id, data in frames:
                    rig.send(can_id, data)
                seen = len(tape.frames)
                while True:
                    rig.step()
                    acks = [
                        m
                        for m in tape.frames[seen:]
                        if m.arbitration_id == fr.ODOM_ACK_ID
                        and hf.unpack_odom_ack(m.data).request_field == 15
                    ]
                    if acks:
                        break
                wall.append(time.perf_counter() - start)
                assert hf.unpack_odom_ack(acks[0].data).result == fr.AckResult.ACK
                latencies.append(acks[0].timestamp - sent_s)
                commands += 1
            else:
                rig.step()
        duration_s = rig.clock.now_s() - 0.5
    return {"frames": tape.frames, "latency": latencies, "wall": wall, "duration": duration_s}


def report(name: str, run: dict[str, object]) -> tuple[float, Counter[int]]:
    frames = run["frames"]
    assert isinstance(frames, list)
    bits: Counter[int] = Counter()
    for msg in frames:
        bits[msg.arbitration_id] += classic_frame_bits(msg.arbitration_id, bytes(msg.data))
    duration = float(run["duration"])  # type: ignore[arg-type]
    load_pct = sum(bits.values()) / duration / BITRATE * 100
    lat = run["latency"]
    wall = run["wall"]
    assert isinstance(lat, list) and isinstance(wall, list)
    print(
        f"{name:<9} {len(frames):6d} frames, {sum(bits.values()) / duration:9.0f} bit/s = "
        f"{load_pct:6.3f} % of {BITRATE // 1000} kbit/s; command latency (bus time) "
        f"median {statistics.median(lat) * 1e3:5.2f} ms, max {max(lat) * 1e3:5.2f} ms "
        f"({len(lat)} commands); wall per command {statistics.median(wall) * 1e3:.1f} ms"
    )
    return load_pct, bits


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--period", type=float, default=1.0)
    args = parser.parse_args()
    print(
        f"lockstep rig, pmir, closed loop, {args.seconds:g} s, one ODOM_SET_POSE command "
        f"(4 frames) every {args.period:g} s"
    )
    plain_pct, _ = report("no key", drive(False, args.seconds, args.period))
    secured_pct, secured_bits = report("SecOC", drive(True, args.seconds, args.period))
    duration = args.seconds
    for can_id, label in ((fr.ODOM_AUTH_ID, "ODOM_AUTH"), (fr.ODOM_FRESHNESS_ID, "ODOM_FRESHNESS")):
        print(f"  {label:<15} {secured_bits[can_id] / duration:8.1f} bit/s")
    print(f"  added bus load: {secured_pct - plain_pct:+.3f} percentage points")


if __name__ == "__main__":
    main()
