"""A firmware reboot mid-drive: the new life's pose is compared with the truth in its own frame.

The rebooted firmware starts at pose 0 at the encoder frame it primed on, wherever the robot
is; the truth goes on in the simulator's frame. Every form of the judge (``analyze``, the
streamed ``analyze_file``, the monitor and the bridge) re-bases the truth at the new life's
origin (``host.judge.compare.life_origin``), so pose vs truth stays a few mm after the reboot
as before it (it said 1.8 m, with the verdict OK). The independent check here takes the
simulator's own truth at the tick whose counts the new firmware primed on and transforms the
truth by hand in float64 (no host code), against the firmware's own pose state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import can
import numpy as np
import pytest

from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from odocan.host.judge.stream_analysis import analyze_file
from odocan.sim.board import FirmwareBoard
from odocan.sim.contract import database
from tests.fault_rig import FaultRig
from tests.test_health_rig import Watch, circle_rig
from tests.test_live_reboot import bridge_of, monitor_of

REBOOT_TICK = 500  # 5 s into the circle
RUN_S = 8.0
STATUS_ID = database().get_message_by_name("ODOM_STATUS").frame_id
FEW_MM = 5e-3  # pose vs truth before the reboot: about 1 mm on pmir's circle


@dataclass
class Record:
    """Per tick after the tick ran: the robot's counts and truth at that instant, and the
    firmware's last integrated counts and pose (float64 from its Q40 / BAM64 integers)."""

    rig: FaultRig
    frames: list[can.Message] = field(default_factory=list)
    counts: list[tuple[int, int]] = field(default_factory=list)
    truth: list[tuple[float, float, float]] = field(default_factory=list)
    firmware: list[tuple[tuple[int, int] | None, float, float, float]] = field(
        default_factory=list)

    def __call__(self, tick: int, frames: list[can.Message]) -> None:
        self.frames.extend(frames)
        self.counts.append(self.rig.vehicle.encoder_counts())
        t = self.rig.vehicle.truth()
        self.truth.append((t.x_m, t.y_m, t.heading_rad))
        odo = self.rig.ecu.odometry
        primed = (odo._left_prev, odo._right_prev) if odo._primed else None
        heading = odo.heading_turns * 2 * math.pi + odo.heading_bam64 / 2**64 * 2 * math.pi
        self.firmware.append((primed, odo.x_q40_m / 2**40, odo.y_q40_m / 2**40, heading))


def run(tmp_path: Path) -> tuple[Record, Watch, Path]:
    """pmir on the circle, a new firmware on the board at ``REBOOT_TICK``; the log written."""
    with circle_rig() as rig:
        watch = Watch(rig)
        record = Record(rig)
        rig.observers.append(record)

        def reboot(k: int) -> None:
            if k == REBOOT_TICK:
                rig.board = FirmwareBoard(rig.fw_bus, rig.params, rig.clock)

        rig.before_board.append(reboot)
        rig.run(RUN_S)
    path = tmp_path / "reboot.log"
    with can.Logger(str(path)) as logger:
        for msg in record.frames:
            logger.on_message_received(msg)
    return record, watch, path


def independent(record: Record, bits: int) -> tuple[tuple[float, float, float], float, float]:
    """The truth at the frame the new firmware primed on (the simulator's, by hand), and the
    largest and last |on-board - truth in the life's frame| (m) over the ticks after it."""
    mask = (1 << bits) - 1
    tick_of = {(left & mask, right & mask): k for k, (left, right) in enumerate(record.counts)}
    primed = record.firmware[REBOOT_TICK][0]
    assert primed is not None
    origin = record.truth[tick_of[(primed[0] & mask, primed[1] & mask)]]
    c, s = math.cos(origin[2]), math.sin(origin[2])
    errors = []
    for last, x, y, _ in record.firmware[REBOOT_TICK + 1:]:
        assert last is not None
        tx, ty, _ = record.truth[tick_of[(last[0] & mask, last[1] & mask)]]
        dx, dy = tx - origin[0], ty - origin[1]  # the truth rotated by minus the origin heading
        errors.append(math.hypot(x - (c * dx + s * dy), y - (-s * dx + c * dy)))
    return origin, max(errors), errors[-1]


@pytest.fixture(scope="module")
def reboot_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Record, Watch, Path]:
    return run(tmp_path_factory.mktemp("truthlife"))


def test_the_independent_check_sees_the_new_life_close_to_the_re_based_truth(
    reboot_run: tuple[Record, Watch, Path],
) -> None:
    record, _, _ = reboot_run
    origin, worst_m, _ = independent(record, min(record.rig.profile.counter_bits, 24))
    assert math.hypot(origin[0], origin[1]) > 0.5  # the reboot came far from the start
    assert worst_m < FEW_MM


def test_analyze_compares_the_new_life_with_the_truth_in_its_frame(
    reboot_run: tuple[Record, Watch, Path],
) -> None:
    record, _, path = reboot_run
    profile = record.rig.profile
    origin, worst_m, _ = independent(record, min(profile.counter_bits, 24))
    analysis = analyze(read_log(path), profile)
    report = analysis.report
    assert analysis.passed
    (boot,) = report["reboots"]
    after = analysis.series["truth_t_s"] >= boot["t_s"] - float(record.frames[0].timestamp)
    assert np.count_nonzero(after) > 20
    life_max_m = float(np.max(analysis.series["truth_position_error_m"][after]))
    assert life_max_m < FEW_MM
    assert life_max_m == pytest.approx(worst_m, abs=1e-3)  # the independent check agrees
    assert report["onboard_vs_truth"]["max_position_error_m"] < FEW_MM
    at = boot["truth_origin"]
    # carried back along the reference by a few frames: the odometry error over them only
    assert at["carried_frames"] < 10
    assert math.hypot(at["x_m"] - origin[0], at["y_m"] - origin[1]) < 1e-3
    assert abs(math.remainder(at["heading_rad"] - origin[2], 2 * math.pi)) < 1e-3
    streamed = analyze_file(path, profile, chunk_frames=997)
    assert streamed["onboard_vs_truth"] == report["onboard_vs_truth"]
    assert streamed["reboots"] == report["reboots"]


def test_the_monitor_and_the_bridge_compare_the_new_life_with_the_truth_in_its_frame(
    reboot_run: tuple[Record, Watch, Path],
) -> None:
    record, watch, path = reboot_run
    profile = record.rig.profile
    origin, _, last_m = independent(record, min(profile.counter_bits, 24))
    live = watch.monitor.tracker
    whole = analyze(read_log(path), profile).report["reboots"][0]["truth_origin"]
    offline = [monitor_of(path, profile.name, "exact").tracker,
               bridge_of(path, profile.name, "exact").tracker]
    for tracker in (live, *offline):
        assert tracker.reference_starts == 2
        assert tracker.vs_truth.max_dpos_m < FEW_MM
        assert tracker.vs_truth.latest["dpos_m"] == pytest.approx(last_m, abs=1.5e-3)
        assert tracker.life_truth.origin is not None
        x0, y0, h0 = tracker.life_truth.origin
        assert (x0, y0, h0) == (whole["x_m"], whole["y_m"], whole["heading_rad"])  # one function
        assert math.hypot(x0 - origin[0], y0 - origin[1]) < 1e-3
        assert abs(math.remainder(h0 - origin[2], 2 * math.pi)) < 1e-3
    assert watch.monitor.health(RUN_S)["state"] == "OK"  # OK, and now the pose it shows is right


def test_without_the_boot_summaries_every_judge_still_compares_in_the_new_life_frame(
    reboot_run: tuple[Record, Watch, Path], tmp_path: Path,
) -> None:
    """The recorder missed the new firmware's summaries of its first second (all UPTIME 0):
    the reboot is told at UPTIME 1; analyze takes the life's start from its first count page
    (ENC_E2E_OK names the frame it primed on), a power-up whatever UPTIME says
    (``reboots.split_lives``), the live judges adopt it at the next pose; the truth is still
    re-based at the life's first truth sample on the reference (the same ``life_origin``), not
    compared in the simulator's frame."""
    record, _, _ = reboot_run
    profile = record.rig.profile
    origin, worst_m, _ = independent(record, min(profile.counter_bits, 24))
    t0 = float(record.frames[0].timestamp)
    first_second = (REBOOT_TICK * 0.01, REBOOT_TICK * 0.01 + 1.0)
    path = tmp_path / "missed.log"
    with can.Logger(str(path)) as logger:
        for msg in record.frames:
            summary = msg.arbitration_id == STATUS_ID and msg.data[1] >> 4 == 0
            if not (summary and first_second[0] <= msg.timestamp - t0 < first_second[1]):
                logger.on_message_received(msg)
    analysis = analyze(read_log(path), profile)
    (boot,) = analysis.report["reboots"]
    assert boot["reference_start"] == "power-up"  # named by the count page, not fitted
    after = analysis.series["truth_t_s"] >= boot["t_s"] - t0 - 1.0
    assert np.count_nonzero(after) > 20
    assert float(np.max(analysis.series["truth_position_error_m"][after])) < FEW_MM
    at = boot["truth_origin"]
    assert math.hypot(at["x_m"] - origin[0], at["y_m"] - origin[1]) < 1e-3
    streamed = analyze_file(path, profile, chunk_frames=997)
    assert streamed["onboard_vs_truth"] == analysis.report["onboard_vs_truth"]
    assert streamed["reboots"] == analysis.report["reboots"]
    for tracker in (monitor_of(path, profile.name, "exact").tracker,
                    bridge_of(path, profile.name, "exact").tracker):
        assert tracker.reference_starts == 2
        # until UPTIME 1 tells the reboot, the live judges compare the new life's poses with
        # the old life (their max shows it, against the reference too); from then on, its frame
        assert tracker.vs_truth.latest["dpos_m"] < FEW_MM
        assert tracker.life_truth.origin is not None
        x0, y0, _ = tracker.life_truth.origin
        # adopted ~1 s later: carried back along the reference from the pose it adopted
        assert math.hypot(x0 - origin[0], y0 - origin[1]) < FEW_MM
    assert worst_m < FEW_MM
