"""A reset, the MCU halted right after the new life's first tick with its mailbox full, and frames
held back on the bus: the live judges must not blame the correct firmware (issue #11, rule 5).

Lockstep drives ``--scenario random --duration 7 --faults
reboot=2.5:0.05,stall=2.56:0.3,delay=0.2:30`` (reset at 2.5 s for 50 ms, halted 0.3 s from 2.56 s,
each frame with probability 0.2 held back 30 ms): ``analyze`` whole and streamed PASS them all
(seeds 1-6, pmir and kobuki), the monitor and the bridge said POSE WRONG on five seeds (mm beyond
the allowance, pmir / kobuki), now all within 0.1 mm:

* seed 4 (0.29 / 0.21 mm): a livefirst silence heard while the reboot waited, before any sample
  held, owes the reboot's placement (``livefirst``, ``livebootstall``);
* seeds 3 and 6 (124.9 / 158.5 mm and 149.7 / 151.9 mm, 132.0-223.7 mrad): the new life started on
  the wrong frame, its first count page counted back over frames the firmware's mailbox had not
  taken; bounded by the power-up pose's word, also held back past the boot summary, and by the
  old life's latest sampled frame (``livebootbound``); then 0.30 / 0.51 mm and 1.22 / 1.68 mm;
* seeds 1 (0.32 / 0.35 mm), 5 (2.45 / 2.99 mm), and 3 and 6 once started right: the halt unseen
  while the life waited, its power-up pose waiting as a sample, or the samples right after the
  halt naming frames the host's E2E check refused (``livebootstall``). Without the delay too:
  pmir random 5 ``reboot=2.5:0.05,stall=2.56:0.3`` 1.84 mm (``NO_DELAY``).

* seed 12 (pmir 2.50 mm and 44.0 mrad, kobuki 3.87 mm and 63.5 mrad; 19.7 mm on main): the frames
  of the new life's first tick held back, its boot summary said INIT, no power-up pose followed,
  and the first count page counted back a lap late; an INIT firmware primes on a frame after its
  summary, the count stepped back whole laps while it stays there (``livebootbound.after_init``).

The start is checked independently, as ``tests/test_reboot_halted_first_tick.py`` does: the
heading is an exact function of the counts since the frame the power-up pose names (float64,
cantools decoding), so the firmware's own HEADING tells where it primed, whatever it merged.
"""

from __future__ import annotations

import math
from pathlib import Path

import can
import pytest

from odocan.host.cli.app import main
from odocan.sim.contract import DBC_PATH
from odocan.sim.robot import load
from tests.dbc_typed import integers, load_can_dbc
from tests.independent_checker import HEADING_LSB_RAD
from tests.judges_cli import assert_live_pass, assert_tamper_wrong_live, both_analyses

REBOOT_S, NAMED_WITHIN_S = 2.5, 0.5
FAULTS = "reboot=2.5:0.05,stall=2.56:0.3,delay=0.2:30"
NO_DELAY = "reboot=2.5:0.05,stall=2.56:0.3"
Drive = tuple[str, int, str]  # robot, seed, faults
INIT_BOOTS: tuple[Drive, ...] = (("pmir", 12, FAULTS), ("kobuki", 12, FAULTS))  # INIT summary
DRIVES: tuple[Drive, ...] = (
    ("pmir", 1, FAULTS), ("pmir", 3, FAULTS), ("pmir", 4, FAULTS), ("pmir", 5, FAULTS),
    ("pmir", 6, FAULTS), ("kobuki", 4, FAULTS), ("kobuki", 6, FAULTS), ("pmir", 5, NO_DELAY),
    *INIT_BOOTS)
CASES = [pytest.param(d, id=f"{d[0]}-{d[1]}{'' if d[2] == FAULTS else '-no-delay'}")
         for d in DRIVES]


@pytest.fixture(scope="module")
def drives(tmp_path_factory: pytest.TempPathFactory) -> dict[Drive, Path]:
    """The lockstep drives (``DRIVES``), each log's path."""
    out = {}
    for robot, seed, faults in DRIVES:
        log = tmp_path_factory.mktemp(f"{robot}{seed}") / "drive.log"
        code = main(["run", "--robot", robot, "--scenario", "random", "--seed", str(seed),
                     "--duration", "7", "--faults", faults, "--firmware", "python",
                     "--log", str(log)])
        assert code == 0, (robot, seed, faults)  # analyze's verdict: PASS
        out[robot, seed, faults] = log
    return out


def _headings_off_lsb(robot: str, log: Path, init: bool = False) -> tuple[int, float]:
    """The new life's samples (ODOM_POSE_X after the reset's power-up pose) and their largest
    heading error (LSB) against the heading of the counts since the frame that power-up pose
    names. A pose names its frame by a 4-bit COUNTER: held back 30 ms, or integrating the halt's
    backlog, it may name any of its COUNTER heard in the ``NAMED_WITHIN_S`` before it; each is
    judged by the closest of those (16 frames apart, a wrong primed frame fits none of them).
    ``init``: a boot summary said INIT (STATE 0, UPTIME 0), no power-up pose follows: the
    firmware primed on the first encoder frame heard after that summary (its mailbox keeps the
    oldest), its samples the poses after it."""
    db = load_can_dbc(DBC_PATH)
    geometry = load(robot).firmware_params()
    per_count_rad = 2 * math.pi / (geometry["counts_per_rev"] * geometry["wheelbase_nm"])
    wrap = 1 << geometry["counter_bits"]

    def heading_rad(counts: tuple[int, int], primed: tuple[int, int]) -> float:
        d_left = (counts[0] - primed[0] + wrap // 2) % wrap - wrap // 2
        d_right = (counts[1] - primed[1] + wrap // 2) % wrap - wrap // 2
        return per_count_rad * (geometry["wheel_radius_right_nm"] * d_right
                                - geometry["wheel_radius_left_nm"] * d_left)

    encoders: list[tuple[float, int, tuple[int, int]]] = []  # (bus time, COUNTER, counts)
    primed: tuple[int, int] | None = None
    init_told = False  # (``init``) the INIT summary heard, the next frame not yet
    worst, samples = 0.0, 0
    with can.LogReader(str(log)) as reader:
        for msg in reader:
            message = db.get_message_by_frame_id(msg.arbitration_id)
            name, s = message.name, integers(message, msg.data, scaling=False)
            if name == "WHEEL_ENCODERS":
                encoders.append((msg.timestamp, s["COUNTER"], (s["LEFT_COUNT"], s["RIGHT_COUNT"])))
                if init_told:
                    primed, init_told = encoders[-1][2], False
            elif (init and name == "ODOM_STATUS" and msg.timestamp >= REBOOT_S and primed is None
                  and s.get("STATE", -1) == 0 and s.get("UPTIME", -1) == 0):
                init_told = True
            elif name == "ODOM_POSE_X" and msg.timestamp >= REBOOT_S:
                if init and primed is None:
                    continue  # the old life's, or before the frame it primed on
                named = [e[2] for e in encoders if e[1] == s["ENC_COUNTER"]
                         and msg.timestamp - e[0] <= NAMED_WITHIN_S]
                if primed is None:  # the power-up pose: (0, 0, 0) at the latest it names
                    if (s["COUNTER"], s["X"], s["HEADING"]) == (0, 0, 0):  # else: the old
                        primed = named[-1]  # life's, held back past the reset
                    continue
                offs = [(s["HEADING"] * HEADING_LSB_RAD - heading_rad(c, primed) + math.pi)
                        % (2 * math.pi) - math.pi for c in named]
                worst = max(worst, min(abs(o) for o in offs) / HEADING_LSB_RAD)
                samples += 1
    return samples, worst


@pytest.mark.parametrize("drive", CASES)
def test_the_firmware_primed_where_its_power_up_pose_named(
        drives: dict[Drive, Path], drive: Drive) -> None:
    """An INIT boot summary's firmware: on the first frame heard after it."""
    samples, worst_lsb = _headings_off_lsb(drive[0], drives[drive], drive in INIT_BOOTS)
    assert samples > 150
    assert worst_lsb <= 1.0, worst_lsb


@pytest.mark.parametrize("drive", CASES)
def test_both_analyses_pass(drives: dict[Drive, Path], drive: Drive) -> None:
    assert both_analyses(drives[drive]) == [0, 0]


@pytest.mark.parametrize("drive", CASES)
def test_the_live_judges_pass_the_correct_firmware(
        drives: dict[Drive, Path], drive: Drive) -> None:
    """Before (mm beyond the allowance, monitor and bridge alike): pmir 1, 3, 4, 5, 6: 0.32,
    124.9, 0.29 (main; 0.06 on ``bootstallwait``), 2.45, 149.7; kobuki 4, 6: 0.21, 151.9; pmir 5
    without the delay 1.84; pmir and kobuki 12 (INIT): 2.50 and 3.87 (19.7 on main)."""
    assert_live_pass(drive[0], drives[drive])


@pytest.mark.parametrize("drive", CASES)
def test_x_10_mm_off_after_the_reset_is_wrong_live(
        drives: dict[Drive, Path], drive: Drive, tmp_path: Path) -> None:
    assert_tamper_wrong_live(drive[0], drives[drive], tmp_path / "tampered.log", REBOOT_S + 1.0)
