"""Frames held back a whole number of encoder periods (``--faults delay=P:10|20|30``): the log
tells which encoder frames the firmware took (issue #11, rule 5).

Found on ``run --robot kobuki --duration 4 --seed 703 --faults delay=0.1:20,seed=703``: run, the
whole and the streamed analyze FAILed a right firmware (heading 22 mrad, DISTANCE 95 mm). The
cause was in the rig, not in the firmware nor in the judges' copy of its E2E rule: a frame sent at
0.28 s and held 20 ms was due at 0.28 + 0.02 = 0.30000000000000004 s (float64), not at the tick's
start (0.3 s), so it waited for the next tick to go on the bus while its log time said 0.300 s,
before the firmware's tick at 0.301 s. The firmware took it a tick later than the log says; its
E2E window (widened once per tick, ``window_per_period``) then differed by one period from the one
every judge counts from the log, and the firmware's later choice of frames (a 16-period lock-out
after a reordered pair) no longer matched the judges': a pose named by its 4-bit ENC_COUNTER was
paired with a frame 16 periods away.

The proof here is a checker written for this test, from the firmware's specification and the log
alone (cantools decoding, float64 odometry): the firmware ticks 1 ms after every 10 ms slot and
drains the frames that reached the bus by then, in bus order; WHEEL_ENCODERS pass E2E Profile 2
with MaxDeltaCounterInit 0 and a window widened by one at every tick (firmware/e2e.py's
``window_per_period``): COUNTER +1 always, +2..+window as frames lost, anything else refused.
Every ODOM_POSE_X must name (ENC_COUNTER) the last frame that checker took by the pose's tick, and
carry its float64 pose within one LSB. It failed before the fix (the firmware's pose named another
frame than the one the log says it had taken).
"""

from __future__ import annotations

import bisect
import math
from pathlib import Path

import can
import cantools
import pytest
from cantools.database.can import Database

from odocan.host.cli.app import main
from odocan.sim.contract import DBC_PATH

TICK_S = 0.01
RECEIVE_LAG_S = 0.001  # the firmware's tick, after the slot's start (sim/board.py TX_LATENCY_S)
COUNTS_PER_REV, RADIUS_M, WHEELBASE_M, COUNTER_BITS = 2578, 0.035, 0.23, 16  # kobuki
X_LSB_M, HEADING_LSB_RAD = 1e-4, 2 * math.pi / 65536
WINDOW_MAX = 15
POSE_PERIOD_S = 0.02  # ODOM_POSE_X's cycle


Signals = dict[str, int]


def _decoded(path: Path) -> tuple[list[tuple[float, Signals]], list[tuple[float, Signals]]]:
    """(time s, raw signals) of the WHEEL_ENCODERS and ODOM_POSE_X frames, in bus order."""
    db = cantools.database.load_file(str(DBC_PATH))
    assert isinstance(db, Database)
    enc, pose = db.get_message_by_name("WHEEL_ENCODERS"), db.get_message_by_name("ODOM_POSE_X")
    found: dict[int, list[tuple[float, Signals]]] = {enc.frame_id: [], pose.frame_id: []}
    with can.LogReader(str(path)) as reader:
        for msg in reader:
            if msg.arbitration_id in found:
                message = enc if msg.arbitration_id == enc.frame_id else pose
                signals = message.decode(bytes(msg.data), scaling=False)
                assert isinstance(signals, dict)
                raw = {name: int(value) for name, value in signals.items()}  # type: ignore[arg-type]
                found[msg.arbitration_id].append((msg.timestamp, raw))
    return found[enc.frame_id], found[pose.frame_id]


def _taken(encoders: list[tuple[float, Signals]]) -> list[tuple[float, Signals]]:
    """The frames the firmware takes, with the tick time it takes each at."""
    taken: list[tuple[float, Signals]] = []
    window, last, i = 0, -1, 0
    for tick in range(1, round(encoders[-1][0] / TICK_S) + 3):
        tick_s = (tick - 1) * TICK_S + RECEIVE_LAG_S
        window = min(WINDOW_MAX, window + 1)
        while i < len(encoders) and encoders[i][0] <= tick_s:
            frame = encoders[i][1]
            i += 1
            delta = (frame["COUNTER"] - last) % 16
            if last < 0 or delta == 1 or 2 <= delta <= window:
                taken.append((tick_s, frame))
                window, last = 0, frame["COUNTER"]
    return taken


def _poses_m(taken: list[tuple[float, Signals]]) -> list[tuple[float, float, float]]:
    """Float64 (x m, y m, heading rad) after each taken frame: the exact arc, from (0, 0, 0) at
    the first (the drive starts at power-up)."""
    per_count_m = 2 * math.pi * RADIUS_M / COUNTS_PER_REV
    x = y = 0.0
    poses = [(0.0, 0.0, 0.0)]
    first, prev = taken[0][1], taken[0][1]
    for _, frame in taken[1:]:
        d_left, d_right = (_wrapped(frame[k] - prev[k]) for k in ("LEFT_COUNT", "RIGHT_COUNT"))
        n_left = _wrapped(frame["LEFT_COUNT"] - first["LEFT_COUNT"])  # within 2^15 on 4 s
        n_right = _wrapped(frame["RIGHT_COUNT"] - first["RIGHT_COUNT"])
        heading = poses[-1][2]
        new_heading = (n_right - n_left) * per_count_m / WHEELBASE_M
        ds = (d_left + d_right) * per_count_m / 2
        dtheta = new_heading - heading
        if abs(dtheta) < 1e-9:
            x += ds * math.cos(heading + dtheta / 2)
            y += ds * math.sin(heading + dtheta / 2)
        else:
            x += ds / dtheta * (math.sin(new_heading) - math.sin(heading))
            y -= ds / dtheta * (math.cos(new_heading) - math.cos(heading))
        poses.append((x, y, new_heading))
        prev = frame
    return poses


def _wrapped(delta: int) -> int:
    """A counter difference on the robot's 16-bit counters (the wire's low bits of them)."""
    half = 1 << (COUNTER_BITS - 1)
    return (delta + half) % (1 << COUNTER_BITS) - half


def _made_s(poses: list[tuple[float, Signals]]) -> list[float]:
    """The tick each ODOM_POSE_X was made in (it may be held back on the bus too): on the 20 ms
    grid of the first pose, the latest slot no later than its bus time whose place in the
    sequence has its COUNTER (a delay of at most two pose periods, 40 ms)."""
    first_s = poses[0][0]
    slots = [round((t - first_s) / POSE_PERIOD_S) for t, _ in poses]
    offsets = [(pose["COUNTER"] - n) % 16 for n, (_, pose) in zip(slots, poses, strict=True)]
    c0 = max(set(offsets), key=offsets.count)  # most frames are on time
    made = []
    for n, (_, pose) in zip(slots, poses, strict=True):
        n_made = next(m for m in (n, n - 1, n - 2) if (c0 + m) % 16 == pose["COUNTER"])
        made.append(first_s + n_made * POSE_PERIOD_S)
    return made


def _mismatches(path: Path) -> list[str]:
    """Every ODOM_POSE_X that does not name and carry the checker's last taken frame."""
    encoders, poses = _decoded(path)
    taken = _taken(encoders)
    expected = _poses_m(taken)
    tick_s = [t for t, _ in taken]
    wrong = []
    for t_s, (_, pose) in zip(_made_s(poses), poses, strict=True):
        k = bisect.bisect_right(tick_s, t_s + 1e-9) - 1  # the last frame taken by its tick
        if k < 0:
            continue
        x_m, _, heading = expected[k]
        d_heading = (pose["HEADING"] * HEADING_LSB_RAD - heading + math.pi) % (2 * math.pi)
        if (pose["ENC_COUNTER"] != taken[k][1]["COUNTER"]
                or abs(pose["X"] * X_LSB_M - x_m) > X_LSB_M
                or abs(d_heading - math.pi) > HEADING_LSB_RAD):
            wrong.append(f"t={t_s:.3f}: ENC_COUNTER {pose['ENC_COUNTER']} X {pose['X']} vs "
                         f"{taken[k][1]['COUNTER']} {x_m * 1e4:.2f}")
    return wrong


@pytest.mark.parametrize("faults", ["delay=0.1:20,seed=703", "delay=0.2:10,seed=703",
                                    "delay=0.2:30,seed=703"])
def test_the_log_tells_which_encoder_frames_the_firmware_took(tmp_path: Path, faults: str) -> None:
    path = tmp_path / "drive.blf"
    code = main(["run", "--robot", "kobuki", "--duration", "4", "--seed", "703", "--faults",
                 faults, "--log", str(path)])
    wrong = _mismatches(path)
    assert not wrong, (len(wrong), wrong[:5])
    assert code == 0
