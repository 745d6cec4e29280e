"""A firmware stalled from before its first pose (issue #11: odocan from outside, on a busy
machine): ``odocan firmware`` on udp_multicast was SIGSTOPped 3 s while it was still INIT (it
had sent only its ODOM_STATUS), and the sim started driving meanwhile. On SIGCONT it took the
three frames its receive FIFO held (primed on the first, stepped the next two), refused the rest
(MAILBOX_OVERFLOW, TIME_LOST) and took frame 249 as one step from frame 2: POSE_UNCERTAIN, as a
halted MCU does after a stall mid-drive. The evidence log is what ``odocan monitor --log``
recorded of that run (``tests/files/firmware_sigstop_before_first_pose.blf``, pmir, random).

``analyze`` FAILed that correct firmware at 550 mm and the monitor said POSE WRONG (1335 mm):
a stall is told from the silence between two samples, and this one has no sample before it, so
the reference integrated frames 3 .. 249 one by one from power-up while the firmware merged
them. This file's float64 odometry (``independent_checker._Odometry`` on cantools-decoded
frames) shows the firmware's first two poses are exactly the stalled MCU's.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from pathlib import Path

import can
import cantools
import numpy as np
import pytest
from cantools.database.can import Database

from odocan.firmware import frames as fw_frames
from odocan.firmware.errors import ErrorMask
from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import HEADING_LSB_RAD, POSITION_LSB_M, analyze
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.reference import Geometry
from odocan.host.judge.samples import Encoders
from odocan.host.judge.stalls import first_after_stall
from odocan.host.judge.stream_first import FirstSilence
from odocan.host.judge.tracking import PoseTracker
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim.contract import DBC_PATH
from odocan.sim.robot import load
from tests.independent_checker import Robot, _Odometry

PMIR = load("pmir")
EVIDENCE = Path(__file__).parent / "files" / "firmware_sigstop_before_first_pose.blf"
WHEEL_ENCODERS, ODOM_POSE_X, ODOM_POSE_Y, ODOM_TWIST = 0x100, 0x200, 0x201, 0x202
RESUMED_AT = 249  # the encoder frame the firmware's second pose names (its merged step's end)


def _decoded() -> tuple[list[dict[str, float]], list[dict[str, float]]]:
    """The log's encoder frames and its (x, y, heading) poses, by cantools, in bus order."""
    db = cantools.database.load_file(str(DBC_PATH))
    assert isinstance(db, Database)
    enc: list[dict[str, float]] = []
    poses: list[dict[str, float]] = []
    pending: dict[str, float] = {}
    for msg in can.LogReader(str(EVIDENCE)):
        if msg.arbitration_id == WHEEL_ENCODERS:
            enc.append(_signals(db, msg))
        elif msg.arbitration_id == ODOM_POSE_X:
            pending = _signals(db, msg)
        elif msg.arbitration_id == ODOM_POSE_Y:
            poses.append({**pending, **_signals(db, msg)})
    return enc, poses


def _signals(db: Database, msg: can.Message) -> dict[str, float]:
    decoded = db.decode_message(msg.arbitration_id, bytes(msg.data), decode_choices=False)
    assert isinstance(decoded, dict)
    return {name: float(value) for name, value in decoded.items()}  # type: ignore[arg-type]


def _odometry(enc: list[dict[str, float]], frames: list[int]) -> _Odometry:
    """Primed on ``frames[0]``, then one step to each next frame (16-bit counters)."""
    odo = _Odometry(Robot(PMIR.counts_per_rev, round(PMIR.wheel_radius_left_m * 1e9),
                          round(PMIR.wheel_radius_right_m * 1e9), round(PMIR.wheelbase_m * 1e9),
                          PMIR.counter_bits), "exact")
    for a, b in itertools.pairwise(frames):
        odo.step(*(round((enc[b][side] - enc[a][side] + 32768) % 65536 - 32768)
                   for side in ("LEFT_COUNT", "RIGHT_COUNT")))
    return odo


def _near(odo: _Odometry, pose: dict[str, float]) -> bool:
    return (math.hypot(odo.x - pose["X"], odo.y - pose["Y"]) <= POSITION_LSB_M
            and abs(odo.heading - pose["HEADING"]) <= HEADING_LSB_RAD)


def test_the_firmware_took_its_fifo_then_one_step() -> None:
    """The evidence is a correct firmware's: its first pose is frames 0, 1, 2 stepped one by
    one, its second frames 3 .. 249 as one step; the fine path is 19 cm away there."""
    enc, poses = _decoded()
    assert _near(_odometry(enc, [0, 1, 2]), poses[0])
    assert _near(_odometry(enc, [0, 1, 2, RESUMED_AT]), poses[1])
    fine = _odometry(enc, list(range(RESUMED_AT + 1)))
    assert math.hypot(fine.x - poses[1]["X"], fine.y - poses[1]["Y"]) > 0.15


def test_analyze_passes_a_firmware_stalled_before_its_first_pose() -> None:
    """Before: FAIL at 549.78 mm (and DISTANCE off by 533.8 mm). Now the first pose is left out
    and the reference is placed at the resumed one, within the merge's allowance."""
    analysis = analyze(read_log(EVIDENCE), PMIR)
    result = analysis.report
    breaks = result["reference_breaks"]
    assert analysis.passed, (result["onboard_vs_reference"], breaks)
    assert main(["analyze", str(EVIDENCE), "--stream", "always"]) == 0  # refused: the whole
    assert breaks["stall_placements"] == 1
    assert breaks["max_offset_beyond_allowance_m"] == 0.0
    assert result["onboard_vs_reference"]["max_position_error_m"] < POSITION_LSB_M
    enc, poses = _decoded()  # the offset absorbed: the merged step's, by float64 odometry
    fine = _odometry(enc, list(range(RESUMED_AT + 1)))
    merged_m = math.hypot(fine.x - poses[1]["X"], fine.y - poses[1]["Y"])
    assert breaks["max_offset_absorbed_m"] == pytest.approx(merged_m, abs=POSITION_LSB_M)


@pytest.mark.parametrize(("from_pose", "bias_lsb"), [(1, 10_000), (20, 3), (300, 2)])
def test_a_wrong_firmware_after_such_a_stall_still_fails(
    tmp_path: Path, from_pose: int, bias_lsb: int
) -> None:
    """X off by ``bias_lsb`` from pose ``from_pose`` on: 1 m at the resumed pose (beyond the
    merge's allowance), 0.3 mm 0.2 s after it, 0.2 mm seconds later. FAIL before and after."""
    wrong = tmp_path / "wrong.blf"
    _write_biased(wrong, from_pose, bias_lsb)
    result = analyze(read_log(wrong), PMIR)
    assert not result.passed, result.report["onboard_vs_reference"]
    monitor, bridge, end_s = _live(wrong)  # the live judges, the stall told or not: FAIL
    assert monitor.health(end_s)["pose_wrongs"]["episodes"] >= 1
    for tracker in (monitor.tracker, bridge.tracker):  # (the bridge's status pose_wrongs)
        assert tracker.wrongs.as_dict()["episodes"] >= 1
        assert tracker.max_beyond_allowance_m > POSITION_LSB_M


@pytest.mark.parametrize(("from_twist", "bias_mm"), [(1, 50), (2, 3), (20, 3)])
def test_a_wrong_distance_after_such_a_stall_fails_every_judge(
    tmp_path: Path, from_twist: int, bias_mm: int
) -> None:
    """DISTANCE raised by ``bias_mm`` from the ``from_twist``-th ODOM_TWIST on: 50 mm at the
    resumed one (8.5 mm beyond the merged step's allowance), 3 mm 20 ms or 0.4 s after it.
    The live DISTANCE judges from the power-up as ``analyze`` does (the first page came before
    any frame): before, it took the resumed twist's offset as its start and PASSed 50 mm."""
    wrong = tmp_path / "wrong.blf"
    _write_twist_biased(wrong, from_twist, bias_mm)
    whole = analyze(read_log(wrong), PMIR).report["onboard_distance_vs_reference"]
    assert not whole["passed"]
    monitor, bridge, _ = _live(wrong)
    for live in (monitor.distance, bridge.distance):
        assert not live.as_dict()["passed"]
        assert live.worst_excess_m == pytest.approx(whole["max_excess_m"], abs=1e-9)


def _write_twist_biased(path: Path, from_twist: int, bias_mm: int) -> None:
    """The evidence with ODOM_TWIST's DISTANCE raised by ``bias_mm`` from its
    ``from_twist``-th frame on (re-sealed: COUNTER, ENC_COUNTER and the velocities kept)."""
    def biased(word: int) -> bytes:
        v, w = (((word >> shift) & 0xFFFF ^ 0x8000) - 0x8000 for shift in (16, 32))
        return fw_frames.pack_odom_twist((word >> 8) & 0xF, (word >> 12) & 0xF, v, w,
                                         (word >> 48) + bias_mm, ErrorMask())
    _rewrite(path, ODOM_TWIST, from_twist, biased)


def _rewrite(path: Path, can_id: int, from_n: int, repack: Callable[[int], bytes]) -> None:
    """The evidence to ``path``, each ``can_id`` frame from its ``from_n``-th on repacked from
    its payload as a little-endian word."""
    seen = 0
    with can.BLFWriter(str(path)) as out:
        for msg in can.LogReader(str(EVIDENCE)):
            if msg.arbitration_id == can_id:
                if seen >= from_n:
                    msg.data = bytearray(repack(int.from_bytes(msg.data, "little")))
                seen += 1
            out.on_message_received(msg)


def _live(path: Path) -> tuple[BusMonitor, RobotTelemetry, float]:
    """The monitor and the bridge fed the log; the last frame's time."""
    monitor = BusMonitor(PMIR)
    bridge = RobotTelemetry("r", Geometry.of(PMIR), "exact", counter_bits=PMIR.counter_bits,
                            publish_hz=10)
    end_s = 0.0
    for msg in can.LogReader(str(path)):
        monitor.feed(msg, now_s=msg.timestamp)
        bridge.feed(msg)
        end_s = msg.timestamp
    return monitor, bridge, end_s


def _write_biased(path: Path, from_pose: int, bias_lsb: int) -> None:
    """The evidence with ODOM_POSE_X's X raised by ``bias_lsb`` from its ``from_pose``-th frame
    on (re-sealed: COUNTER, ENC_COUNTER and HEADING kept)."""
    def biased(word: int) -> bytes:
        x_raw = (word >> 16) & 0xFFFF_FFFF
        x_100um = x_raw - (1 << 32) if x_raw >> 31 else x_raw
        return fw_frames.pack_odom_pose_x((word >> 8) & 0xF, (word >> 12) & 0xF,
                                          x_100um + bias_lsb, word >> 48, ErrorMask())
    _rewrite(path, ODOM_POSE_X, from_pose, biased)


@pytest.mark.parametrize(("status_s", "first_pose_s", "stalled"), [
    (0.30, 0.40, True),  # silent 100 ms with 10 encoder frames logged on time: a stall
    (0.30, 0.36, False),  # 60 ms: a firmware that primed and spoke within its cycles
    (None, 0.40, False),  # no frame of its own before: nothing tells a stall from a late boot
])
def test_the_stream_refuses_a_life_whose_first_pose_follows_a_silence(
    status_s: float | None, first_pose_s: float, stalled: bool
) -> None:
    """``stream_first.FirstSilence`` over two chunks: the streamed judge refuses (and the
    whole log is judged) exactly where the whole log's ``stalls.first_after_stall`` leaves the
    first pose out; the live judges' (``livefirst.FirstStall``, on the tracker's window) names
    the same frame."""
    enc_s = np.round(np.arange(0.30, 0.50, 0.01), 6)
    silence = FirstSilence()
    status = np.array([] if status_s is None else [status_s])
    none = np.zeros(0)
    silence.feed(status, enc_s[:5], none, 0.01)  # the first chunk: no pose yet
    silence.feed(none, enc_s[5:], np.array([first_pose_s, first_pose_s + 0.02]), 0.01)
    assert silence.decided
    assert silence.stalled is stalled
    n = np.arange(len(enc_s), dtype=np.int64)
    encoders = Encoders(n, n % 16, n, 0 * n, 0 * n, enc_s, 0.01)
    whole = first_after_stall(first_pose_s, encoders, None if status_s is None else status)
    assert (whole is not None) is stalled
    tracker = PoseTracker(Geometry.of(PMIR), PMIR.counter_bits, "exact")  # live: its window
    for k, t_s in enumerate(enc_s.tolist()):
        if status_s is not None and status_s <= t_s and not tracker.first.alive:
            tracker.on_status(status_s)
        tracker.on_encoders(k % 16, 0, 0, t_s)
    assert tracker.first.primed(tracker, first_pose_s) == whole


def test_the_live_judges_pass_a_firmware_stalled_before_its_first_pose() -> None:
    """The monitor said POSE WRONG (1335 mm) on this run, live, and DISTANCE WRONG; the bridge
    judges alike."""
    monitor, bridge, end_s = _live(EVIDENCE)
    health = monitor.health(end_s)
    assert health["pose_wrongs"]["episodes"] == 0
    assert not health["why"][0].startswith("ODOM_TWIST DISTANCE"), health["why"]
    assert monitor.distance.as_dict()["start"] == "power-up"  # as analyze's (its first page)
    for tracker in (monitor.tracker, bridge.tracker):
        assert tracker.stall.stalls == 1
        assert tracker.placer.placements.max_beyond_m == 0.0
        assert tracker.vs_reference.max_dpos_m < 1.5 * POSITION_LSB_M
