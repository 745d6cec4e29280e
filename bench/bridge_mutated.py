"""A fault-mutated copy of a ``bench/bridge_frames.py`` recording, and the bridge's verdicts on
it: the check that a cheaper per-frame path judges faults as before (clean drives: the digest
of ``bridge_frames.py`` alone). Each robot's frames get one fault by its index: 0 clean,
1 5 % dropped, 2 silences (0.3 s in each 1.5 s), 3 3 % repeated, 4 3 % CRC errors, 5 CRC-right
WHEEL_ENCODERS twins of other counts, 6 stamps bunched (a starved recorder: 60 ms of frames in
each 0.5 s stamped in a burst), 7 ODOM_POSE_X 2 LSB off (CRC right: POSE WRONG), 8 0..3 ms of
jitter on every stamp, 9 20 % dropped and bunched; robots 10 mod 20 (``KINDS``) have
ENC_E2E_OK counted short (spans of frames the firmware merged: liveskip's allowance) and 17
(mod 20) too, with ODOM_TWIST DISTANCE 2 LSB high (DISTANCE WRONG). Printed: the digest of
every publication and final status (``bridge_frames.run_once``) and each robot's verdicts; two
trees judge alike when both are the same:

    PYTHONPATH=. .venv/bin/python bench/bridge_frames.py --robots 50 --ticks 600 \
        --record /tmp/fleet50.pkl
    PYTHONPATH=<tree> .venv/bin/python bench/bridge_mutated.py /tmp/fleet50.pkl
"""

from __future__ import annotations

import argparse
import json
import pickle
import random
import sys
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import bridge_frames  # bench/bridge_frames.py

import odocan.host.mqtt.topics as topics
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.host.protocol.e2e import e2e_messages
from odocan.host.protocol.e2e_crc import crc8h2f_p02_one
from odocan.sim.contract import database

Frame = tuple[float, int, bytes]
KINDS = {10: 10, 17: 11}  # robot index mod 20: a fault of its own (else index mod 10)
ENC, POSE_X, TWIST, STATUS = 0x100, 0x200, 0x202, 0x380  # the shipped DBC's identifiers
IDS = {key: config.data_ids for key, config in e2e_messages(database()).items()}


def _crc(can_id: int, data: bytearray) -> bytes:
    """``data`` with its Profile 2 CRC made right."""
    ids = IDS.get(can_id)
    if ids is not None:
        data[0] = crc8h2f_p02_one(bytes(data), ids[data[1] & 0xF])
    return bytes(data)


def _edited(kind: int, t_s: float, can_id: int, data: bytes, rng: random.Random,
            short: list[int]) -> bytes:
    """The frame's payload under ``kind``'s edits (``short``: ENC_E2E_OK's deficit so far)."""
    edit = bytearray(data)
    if kind == 4 and rng.random() < 0.03:
        edit[0] ^= 0x5A
        return bytes(edit)
    if kind == 7 and can_id == POSE_X and t_s > 1.0:
        x = int.from_bytes(edit[2:6], "little", signed=True) + 2
        edit[2:6] = x.to_bytes(4, "little", signed=True)
        return _crc(can_id, edit)
    if kind == 11 and can_id == TWIST and t_s > 2.0:
        edit[6:8] = ((int.from_bytes(edit[6:8], "little") + 2) & 0xFFFF).to_bytes(2, "little")
        data = _crc(can_id, edit)
    if kind in (10, 11) and can_id == STATUS and data[1] >> 4 == 2:  # the ENC_E2E page
        short[0] += rng.choice([0, 0, 1, 2, 25] if kind == 10 else [0, 0, 1])
        edit = bytearray(data)
        edit[2:4] = ((int.from_bytes(edit[2:4], "little") - short[0]) & 0xFFFF).to_bytes(
            2, "little")
        return _crc(can_id, edit)
    return data


def mutate(kind: int, frames: list[Frame], rng: random.Random) -> list[Frame]:
    """One robot's frames with fault ``kind`` (module docstring), in their order."""
    out: list[Frame] = []
    short = [0]
    for t_s, can_id, data in frames:
        if ((kind == 1 and rng.random() < 0.05) or (kind == 2 and t_s % 1.5 > 1.2)
                or (kind == 9 and rng.random() < 0.2)):
            continue
        data = _edited(kind, t_s, can_id, data, rng, short)
        if kind == 8:
            t_s += rng.random() * 0.003
        if kind in (6, 9) and t_s % 0.5 < 0.06:
            t_s += 0.06 - (t_s % 0.5) * 0.99
        out.append((t_s, can_id, data))
        if kind == 3 and rng.random() < 0.03:
            out.append((t_s + 0.0001, can_id, data))
        if kind == 5 and can_id == ENC and rng.random() < 0.05:
            twin = bytearray(data)
            twin[3] ^= 0x01
            out.append((t_s + 0.0002, can_id, _crc(can_id, twin)))
    return out


def mutated(recording: bridge_frames.Recording, seed: int) -> bridge_frames.Recording:
    """Every robot's frames mutated, put back in the batches they came in (by their rank)."""
    robots, batches = recording
    rng = random.Random(seed)
    heard: list[list[tuple[int, Frame]]] = [[] for _ in range(robots)]
    for k, batch in enumerate(batches):
        for index, frame in batch:
            heard[index].append((k, frame))
    out: list[list[tuple[int, Frame]]] = [[] for _ in batches]
    for index in range(robots):
        kind = KINDS.get(index % 20, index % 10)
        ranks = [k for k, _ in heard[index]]
        for j, frame in enumerate(mutate(kind, [f for _, f in heard[index]], rng)):
            out[ranks[min(j, len(ranks) - 1)]].append((index, frame))
    return robots, out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("frames", metavar="PATH", help="a bridge_frames.py --record recording")
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args()
    recording = mutated(pickle.loads(Path(args.frames).read_bytes()), args.seed)
    setattr(topics.time, "time", lambda: 1.0)  # noqa: B010 (as bridge_frames: a pinned clock)
    made: list[RobotTelemetry] = []
    plain = bridge_frames.telemetries
    bridge_frames.telemetries = lambda robots: made.extend(plain(robots)) or made  # type: ignore[assignment]
    _, digest, published = bridge_frames.run_once(recording, None, Counter())
    tally: Counter[str] = Counter()
    for index, telemetry in enumerate(made):
        status = telemetry.status()[1]
        wrong = [name for name, failed in (
            ("DISTANCE", not status["distance"]["passed"]),
            ("TWIST", status["twist"].get("passed") is False),
            ("POSE", bool(status["pose_wrongs"]["episodes"]))) if failed]
        tally["FAIL" if wrong else "PASS"] += 1
        print(f"robot {index:3d} fault {KINDS.get(index % 20, index % 10):2d}: "
              f"{' '.join(wrong) or 'PASS'}, holds {telemetry.hold.settle.holds}, "
              f"{json.dumps(status['distance'], sort_keys=True)}")
    print(f"digest {digest}, {published} publications, {dict(sorted(tally.items()))}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
