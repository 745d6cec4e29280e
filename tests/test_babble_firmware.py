"""What the firmware makes of a babbling node that starves its encoder frames (issue #16.4).

A stuck node on the motor controller's side (``--faults babble=1500:0x050:2:0.5``: data frames on
ID 0x050, below WHEEL_ENCODERS' 0x100, 1500 per second from 2.0 s to 2.5 s) on a 125 kbit/s
bit-timed bus asks for more than the wire carries (one 8-byte frame of 0x050 takes about 1 ms),
so at every bus idle the babbler's backlog wins arbitration and every other frame waits in its
controller's transmit buffer until the backlog has drained, about 0.25 s after the babble ends.

The firmware's watchdog sees no WHEEL_ENCODERS for 10 periods and goes DEGRADED with
ENCODER_TIMEOUT; when the queued encoder frames arrive it is OK again after 5 of them. The host
learns both only from ODOM_STATUS, which starves too: it hears DEGRADED late, with OK right
behind it. The E2E layer loses nothing (a frame that waits is not lost) and, because the encoder
counts are absolute, no distance is lost either: the final on-board pose is on the truth (0.6 mm).
Inside the firmware the pose only lags: at all but 5 of 450 ticks it is a pose the same drive
reaches without the babble (at most 66 ticks earlier; the 5 fall while the queued frames arrive
and were not looked into), and from 3.03 s on it is bit-identical to it.

The judge does not see it so: while the backlog drains its comparison reaches 227 mm and 3.06 rad
on-board vs truth, it restarts its reference three times ("firmware_stall") and FAILs the run
on-board vs reference (111 mm) and on ODOM_TWIST: a FAIL that blames a correct firmware (a strict
xfail below, for whoever mends the judge).
"""

from __future__ import annotations

import json
import subprocess
import sys
import uuid
from pathlib import Path

import can
import pytest

from odocan.firmware import frames as fr
from odocan.firmware.errors import ErrorFlag
from odocan.sim.contract import database
from odocan.sim.faults import FaultInjectingBus, FaultSpec
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.robot import load
from tests.dbc_typed import decode, number

BABBLE = "babble=1500:0x050:2:0.5,seed=3"
BITRATE = 125_000
DURATION_S = 4.5


def _status_summaries(reader: can.BufferedReader) -> list[tuple[float, str, str, int]]:
    """(end-of-frame s, STATE, REASON, ERROR_MASK) of every ODOM_STATUS summary the host heard."""
    db = database()
    out = []
    while (msg := reader.get_message(0)) is not None:
        if msg.arbitration_id != fr.ODOM_STATUS_ID:
            continue
        signals = decode(db, msg.arbitration_id, msg.data, decode_choices=True)
        if signals["PAGE"] == "SUMMARY":
            mask = int(number(signals["ERROR_MASK"]))
            out.append((msg.timestamp, str(signals["STATE"]), str(signals["REASON"]), mask))
    return out


def _transitions(states: list[tuple[float, str, str]]) -> list[tuple[float, str, str]]:
    """The entries where (state, reason) changes."""
    return [s for i, s in enumerate(states) if i == 0 or s[1:] != states[i - 1][1:]]


def test_babble_below_wheel_encoders_degrades_the_firmware_and_it_recovers() -> None:
    reader = can.BufferedReader()
    config = RigConfig(
        load("pmir"),
        channel=f"babble-{uuid.uuid4().hex}",
        faults=FaultSpec.parse(BABBLE),
        bitrate=BITRATE,
        seed=3,
    )
    firmware: list[tuple[float, str, str]] = []
    with LockstepRig(config, [reader]) as rig:
        for k in range(round(DURATION_S * 100)):
            rig.step()
            ecu = rig.board.ecu
            firmware.append((k * 0.01, ecu.state.name, ecu.reason.name))
        sim_bus = rig._buses[0]  # the motor controller's handle, wrapped by its faults
        assert isinstance(sim_bus, FaultInjectingBus)
        babbled = sim_bus.injected_by_id["babble", 0x050]
    summaries = _status_summaries(reader)
    on_board = _transitions(firmware)
    heard = _transitions([(t, s, r) for t, s, r, _ in summaries])
    print(f"\n{babbled} babble frames on 0x050; firmware: {on_board}; host heard: {heard}")
    assert 600 < babbled < 900  # 1500/s for 0.5 s
    # the firmware: OK, DEGRADED 10-20 periods after the babble began, OK once it has drained
    assert [(s, r) for _, s, r in on_board] == [
        ("OK", "NONE"), ("DEGRADED", "ENCODER_TIMEOUT"), ("OK", "NONE")
    ]
    assert 2.10 <= on_board[1][0] <= 2.20
    assert 2.5 < on_board[2][0] < 3.0
    # the host: the same transitions, from ODOM_STATUS, later than they happened
    assert [(s, r) for _, s, r in heard] == [
        ("OK", "NONE"), ("DEGRADED", "ENCODER_TIMEOUT"), ("OK", "NONE")
    ]
    assert heard[1][0] > on_board[2][0]  # DEGRADED reaches the host after the firmware recovered
    assert summaries[-1][3] & ErrorFlag.ENCODER_TIMEOUT  # sticky in the error mask


def test_babble_starves_the_encoders_but_loses_neither_frames_nor_distance(tmp_path: Path) -> None:
    report_path = tmp_path / "babble.json"
    done = subprocess.run(
        [sys.executable, "-m", "odocan", "run", "-b", str(BITRATE), "--seed", "3",
         "--duration", str(DURATION_S), "--faults", BABBLE, "--report", str(report_path)],
        capture_output=True, text=True, timeout=300,
    )
    assert done.returncode in (0, 1), done.stderr
    report = json.loads(report_path.read_text())
    rows = {row["name"]: row for row in report["bus"]["messages"]}
    encoders = rows["WHEEL_ENCODERS"]
    print(
        f"\nWHEEL_ENCODERS: {encoders['frames']} frames, max latency "
        f"{encoders['max_latency_us'] / 1000:.1f} ms, {encoders['late']} late; "
        f"E2E {report['e2e']['WHEEL_ENCODERS']}; on-board vs truth {report['onboard_vs_truth']}"
    )
    assert "WHEEL_ENCODERS" in report["bus"]["starved"]
    assert encoders["max_latency_us"] > 400_000  # starved for the whole babble and its backlog
    assert encoders["late"] > 40
    assert encoders["frames"] == DURATION_S * 100  # every one sent in the end
    assert report["e2e"]["WHEEL_ENCODERS"]["lost"] == 0  # waiting is not losing
    assert report["onboard_vs_truth"]["final_position_error_m"] < 0.002  # nor is distance lost


def test_babble_spec_takes_an_id_and_a_window_and_prints_back() -> None:
    spec = FaultSpec.parse("babble=1500:0x050:2:0.5,seed=3")
    assert (spec.babble, spec.babble_id) == (1500.0, 0x050)
    assert spec.babble_window is not None
    assert (spec.babble_window.at_s, spec.babble_window.duration_s) == (2.0, 0.5)
    assert str(spec) == "babble=1500:0x050:2:0.5,seed=3"
    assert FaultSpec.parse("babble=20:80").babble_id == 0x050  # decimal IDs too
    assert str(FaultSpec.parse("babble=20")) == "babble=20,seed=0"  # random IDs, as before


def test_a_stuck_babbler_sends_data_frames_on_its_id_inside_its_window_only() -> None:
    channel = f"babble-{uuid.uuid4().hex}"
    spec = FaultSpec.parse("babble=1000:0x1ABCDE:1:0.5,seed=2")
    with (
        can.Bus(interface="virtual", channel=channel, preserve_timestamps=True) as raw,
        can.Bus(interface="virtual", channel=channel) as ear,
    ):
        bus = FaultInjectingBus(raw, spec)
        for k in range(300):  # 3 s of a sender at 100 Hz
            bus.send(can.Message(timestamp=k * 0.01, arbitration_id=0x100, data=bytes(8)))
        got = []
        while (msg := ear.recv(0)) is not None:
            got.append(msg)
        bus.shutdown()  # and the wrapped handle with it
    babble = [m for m in got if m.arbitration_id != 0x100]
    print(f"\n{len(babble)} babble frames in [1, 1.5) s at 1000/s")
    assert 400 < len(babble) < 600
    assert all(m.arbitration_id == 0x1ABCDE and m.is_extended_id for m in babble)
    assert all(m.dlc == 8 and not (m.is_error_frame or m.is_remote_frame) for m in babble)
    assert all(1.0 <= m.timestamp < 1.5 for m in babble)
    assert bus.injected["babble"] == len(babble)


def _firmware_poses(faults: FaultSpec | None) -> list[tuple[int, int, int]]:
    """The firmware's (x Q40 m, y Q40 m, heading BAM64) after every tick of the babble drive."""
    config = RigConfig(load("pmir"), channel=f"babble-{uuid.uuid4().hex}", faults=faults,
                       bitrate=BITRATE, seed=3)
    poses = []
    with LockstepRig(config, []) as rig:
        for _ in range(round(DURATION_S * 100)):
            rig.step()
            odometry = rig.board.ecu.odometry
            poses.append((odometry.x_q40_m, odometry.y_q40_m, odometry.heading_bam64))
    return poses


def test_the_starved_firmware_lags_then_is_bit_identical_to_the_undisturbed_drive() -> None:
    clean = _firmware_poses(None)
    starved = _firmware_poses(FaultSpec.parse(BABBLE))
    tick_of = {pose: k for k, pose in enumerate(clean)}
    lags = [k - tick_of[pose] for k, pose in enumerate(starved) if pose in tick_of]
    same_from = next(k for k in range(len(clean)) if starved[k:] == clean[k:])
    print(f"\nbit-identical from tick {same_from}; lag up to {max(lags)} ticks; "
          f"{len(starved) - len(lags)} ticks at a pose the clean drive never has")
    assert starved[:200] == clean[:200]  # before the babble: the same drive
    assert max(lags) > 40  # it does lag: the encoder frames waited
    assert same_from < 310  # and catches up exactly once the backlog has drained
    assert starved[-1] == clean[-1]


@pytest.mark.xfail(strict=True, reason="the judge takes the starved stretch for firmware stalls "
                   "and FAILs a firmware whose pose only lagged (docs/bus.md)")
def test_the_judge_passes_a_firmware_whose_pose_only_lagged(tmp_path: Path) -> None:
    report_path = tmp_path / "babble.json"
    subprocess.run(
        [sys.executable, "-m", "odocan", "run", "-b", str(BITRATE), "--seed", "3",
         "--duration", str(DURATION_S), "--faults", BABBLE, "--report", str(report_path)],
        capture_output=True, text=True, timeout=300, check=False,
    )
    assert json.loads(report_path.read_text())["passed"] is True
