"""The thirty-seventh pass's outside trial (issue #11): odd robots (custom profiles: 32-bit
counters, 12 counts per revolution, a 1 cm wheelbase, unequal wheel radii, a robot whose every
scenario saturates at its MAX_WHEEL_SPEED, 2^20 and 2^24 counts per revolution), the C firmware
beside the Python one, 10..60 s drives of every scenario but straight, and the fault mixes a rig
would use, alone and by two. Each drive judged by the four judges (``run``, ``analyze`` whole
and streamed, the live monitor and the bridge's judge), its firmware's every step watched
(``tests.fw_watch``), and again with ODOM_POSE_X raised 10 mm from mid-drive on.

Pinned here: a sample of the passes (each judge PASSes the correct firmware, FAILs the tampered
pose, and the C firmware writes the Python one's log byte for byte), and the wrong verdicts
found: ``STALL_LATE_RUN`` (fixed for run and ``analyze``), and ``SLOW16_LIVE``,
``STALL_LIVE_HELD`` and ``LIVE_LOSS_SPAN`` (fixed for the live judges: one cause, the encoder
frames after the MCU's halt judged by the stamps, ``host.protocol.e2e_halts``).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from odocan.host.cli.app import main
from odocan.sim import cboard
from odocan.sim.robot import RobotProfile, to_toml
from tests.fw_watch import Watch
from tests.judges_cli import fails_by_position, live_judges, raise_x_10_mm, watched_run
from tests.requires import require_executables

PROFILES = {  # odd robots a rig may be configured for (names are the tests' own)
    "cpr12": RobotProfile("cpr12", 12, 0.05, 0.05, 0.25, 16, 2.0),  # 26 mm of rim per count
    "wb1cm": RobotProfile("wb1cm", 1000, 0.03, 0.03, 0.01, 16, 1.5),  # a 1 cm wheelbase
    "c32": RobotProfile("c32", 4096, 0.08, 0.08, 0.3, 32, 4.0),  # 32-bit counters
    "fast": RobotProfile("fast", 2000, 0.05, 0.05, 0.3, 16, 0.45),  # every scenario saturates
    # 2^24 counts per revolution on 16-bit counters: readable only at 0.03 m/s, which every
    # scenario saturates at (a step of 3 periods reads wrapped: the firmware's COUNTER_RESET)
    "slow16": RobotProfile("slow16", 2**24, 0.05, 0.05, 0.3, 16, 0.03),
}
Spec = tuple[str, str, int, int, str]  # profile, scenario, seed, duration s, faults
TAMPER_MM = 10
STALL_DELAY = "stall=3.0:0.05,delay=0.1:30"
LIVE_LOSS_SPAN = (  # fixed (e2e_halts): the live judges FAIL the tamper, 9.97 mm beyond
    "issue #11: cpr12 figure8 seed 74, 10 s, stall=3.0:0.05,delay=0.1:30: ODOM_POSE_X raised 10 mm "
    "from 5 s on FAILs run's firmware twin and both analyzes (9.92 mm beyond), but the monitor "
    "and the bridge's judge stay OK, 0.0555 mm beyond, the samples 6.4..9.97 mm off. Traced: "
    "after the 50 ms halt the firmware's E2E locked out under the 30 ms delays (ENC_E2E_OK +8, "
    "ENC_E2E_LOST +43 between the pages of 3.15 and 3.78 s); the whole-log judge's model "
    "refused the same frames (9 taken: gaps, lost beyond them -13), the live model took 54, so "
    "livelosses.on_page read 34 frames the firmware lost beyond the bus's gaps and opened a "
    "worst-runs span of 13.70 mm from frame 273 (with 1.37 mm from 222 and 5.48 mm from 327: "
    "20.55 mm for every later sample of the life), which a 12-count wheel's 26 mm per count "
    "makes that wide; analyze's loss_allowance_m is 0.0")
STALL_LATE_RUN = (  # fixed (latenames._joins_run): run and both analyzes PASS it now
    "circle seed 74, 15 s, stall=4.5:0.05,delay=0.1:30 (pmir; kobuki and the unequal wheels' "
    "robot alike; neither fault alone): a correct firmware (every step within 1/1000 LSB, C "
    "and Python the same bytes) FAILed run, analyze whole and streamed by 79.47 mm beyond "
    "(78.5 mrad). latenames.LateScan read the first ODOM_POSE_X after the 50 ms MCU halt (own "
    "COUNTER 1, heard on time at 4.551 s) as held back 50 ms: the frame before it (COUNTER 15, "
    "30 ms late, a straggler sent before the latest heard in order) was late, so _top_send put "
    "its send one period after that one (COUNTER 0 at 4.481 s): the halt's silence read as "
    "lateness; the 15 sends after it continued that run (_run_send), each placed 50 ms early. "
    "COUNTER 13 (heard 4.791 s, naming the late encoder COUNTER 12 heard 1 ms before it, seq "
    "492), placed at 4.741 s, named from encoder COUNTER 3 (seq 483) the frame a lap back (seq "
    "476): the pose of 4.79 s against the reference of 4.63 s")
STALL_LIVE_HELD = (  # fixed (e2e_halts): the live judges PASS it, 0.071 mm (half LSBs)
    "issue #11: the same drive (STALL_LATE_RUN) FAILs the monitor and the bridge by 79.26 mm "
    "beyond (79.80 mm, 81.7 mrad, one sample at 5.131 s), a cause of their own: after the "
    "firmware took the late encoder COUNTER 1 at 5.000 s its E2E locked out (refused 5.01 to "
    "5.13 s, the on-time COUNTER 1 at 5.130 s as REPEATED: its pose names COUNTER 1 with the "
    "same X from 5.011 to 5.131 s); the live E2E model took every on-time frame (OK), and the "
    "pose at 5.131 s (its own COUNTER 2 on: the one between held back to 5.141 s, so no held "
    "repeat) names COUNTER 1 from the frame of 5.130 s, 16 periods on; analyze's model refused "
    "them as the firmware did")
SLOW16_LIVE = (  # fixed (e2e_halts, livesecond): every judge PASSes it, and FAILs the tamper
    "slow16 (2^24 counts per revolution, 16-bit counters, 0.03 m/s) random seed 43, 10 s, "
    "stall=3:0.05,delay=0.1:30: run and both analyzes PASSed the correct firmware (0.048 mm), "
    "the monitor and the bridge said POSE WRONG, 3 episodes, 5.05 mm beyond. Traced: the MCU "
    "halted 3.00..3.05 s drained its backlog at once, so its E2E window trailed the stamps: it "
    "refused the on-time COUNTER 2 and 3 of 3.06 and 3.07 s and took COUNTER 1, held back on "
    "the bus to 3.08 s (its poses name it from 3.091 s), then refused the 12 frames on time "
    "after it and re-primed at 3.22 s (a step of 14 periods). analyze took 2 and 3 by the "
    "stamps and 1 by the poses' evidence (refusing the 12); the live receiver refused 1 by the "
    "stamps (every reading agreed: no hold) and took the 12, so it missed the re-prime. Past "
    "that, the step from 3 back to 1 reads 14 periods: analyze chose it taken by the next pose "
    "(evidencechoice), the live judges re-primed (one choice at a time, the one of 2.79 s "
    "waiting for its pages) and lost a period of motion: 0.50 mm beyond")
SLOW16: Spec = ("slow16", "random", 43, 10, STALL_DELAY)
PASSES: dict[str, Spec] = {  # a sample of the trial's passes, every judge right both ways
    "wb1cm_random_51": ("wb1cm", "random", 51, 10, "busoff=6.0:0.1,dup=0.05"),
    "c32_figure8_77": ("c32", "figure8", 77, 10, "stall=4.0:0.05,drop=0.02"),
}
PMIR_74: Spec = ("pmir", "circle", 74, 15, "stall=4.5:0.05,delay=0.1:30")
LIVE_MISSES: dict[str, Spec] = {"cpr12_figure8_74": ("cpr12", "figure8", 74, 10, STALL_DELAY)}
FALSE_FAILS: dict[str, tuple[Spec, str]] = {  # fixed, each: every judge PASSes it now
    "pmir_circle_74": (PMIR_74, STALL_LIVE_HELD),
    "slow16_random_43": (SLOW16, SLOW16_LIVE),
}


@pytest.fixture(scope="module")
def robots(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """Each profile's TOML path (the CLI's ``--robot``)."""
    folder = tmp_path_factory.mktemp("robots")
    paths = {"pmir": "pmir", "kobuki": "kobuki"}
    for name, profile in PROFILES.items():
        (path := folder / f"{name}.toml").write_text(to_toml(profile))
        paths[name] = str(path)
    return paths


def analyze_exit(log: Path, robot: str, stream: str) -> int:
    """``odocan analyze LOG --robot ROBOT --stream STREAM``'s exit code."""
    return main(["analyze", str(log), "--robot", robot, "--stream", stream])


def _judged(log: Path, robot: str) -> tuple[list[int], list[float]]:
    """``analyze --robot`` whole and streamed exit codes, and the live monitor's and bridge's
    largest position error beyond their allowance (m), their wrong episodes counted as 1 m."""
    codes = [analyze_exit(log, robot, s) for s in ("never", "always")]
    beyond = [1.0 if judge.tracker.wrongs.count else judge.tracker.max_beyond_allowance_m
              for judge in live_judges(robot, log)]
    return codes, beyond


def _drive(spec: Spec, robots: dict[str, str], log: Path) -> tuple[Watch, int]:
    """The watched Python-firmware drive of ``spec`` into ``log``: its watch and run's exit."""
    robot, scenario, seed, duration, faults = spec
    return watched_run(log, robots[robot], scenario, seed, duration, faults)


def _assert_right(watch: Watch) -> None:
    """The firmware integrated over 400 steps, each within 1/1000 LSB of float64."""
    assert watch.steps > 400
    assert watch.within_a_thousandth_lsb(), (watch.worst_m, watch.worst_rad)


def _both_ways(spec: Spec, robots: dict[str, str], tmp_path: Path) -> list[object]:
    """Run's exit, then the judges of the log (``_judged``) and of the log with X raised 10 mm
    from mid-drive: [run, analyze whole, streamed, monitor, bridge] x 2, beyond in mm."""
    log, tampered = tmp_path / "drive.log", tmp_path / "tampered.log"
    watch, code = _drive(spec, robots, log)
    _assert_right(watch)
    codes, beyond = _judged(log, robots[spec[0]])
    assert raise_x_10_mm(log, tampered, spec[3] / 2) > 100
    t_codes, t_beyond = _judged(tampered, robots[spec[0]])
    return [code, *codes, *(b > 5e-3 for b in beyond), *t_codes, *(b > 5e-3 for b in t_beyond)]


RIGHT = [0, 0, 0, False, False, 1, 1, True, True]  # PASS both ways, FAIL the tampered pose


@pytest.mark.parametrize("name", PASSES)
def test_odd_robot_passes_and_its_tamper_fails(name: str, robots: dict[str, str],
                                               tmp_path: Path) -> None:
    assert _both_ways(PASSES[name], robots, tmp_path) == RIGHT


@pytest.mark.parametrize("name", LIVE_MISSES)
def test_live_judges_fail_a_10_mm_tamper_after_a_lock_out(name: str, robots: dict[str, str],
                                                          tmp_path: Path) -> None:
    """``LIVE_LOSS_SPAN`` (fixed): the live judges hold the frames after the halt for the
    firmware's poses (``e2e_halts``), take what it took, and FAIL the tamper."""
    assert _both_ways(LIVE_MISSES[name], robots, tmp_path) == RIGHT


def test_run_and_analyze_pass_a_halt_after_a_straggler(robots: dict[str, str],
                                                      tmp_path: Path) -> None:
    """``STALL_LATE_RUN`` (fixed): run, analyze whole and streamed PASS the correct firmware,
    and FAIL X raised 10 mm from mid-drive on by the position (over 9 mm beyond)."""
    log, tampered = tmp_path / "drive.log", tmp_path / "tampered.log"
    watch, code = _drive(PMIR_74, robots, log)
    _assert_right(watch)
    assert [code, *(analyze_exit(log, "pmir", s) for s in ("never", "always"))] == [0, 0, 0]
    assert raise_x_10_mm(log, tampered, PMIR_74[3] / 2) > 300
    assert fails_by_position(tampered, tmp_path, 9e-3) == []


@pytest.mark.parametrize("name", FALSE_FAILS)
def test_every_judge_passes_the_correct_firmware(name: str, robots: dict[str, str],
                                                 tmp_path: Path) -> None:
    """The drive's correct firmware PASSes run, both analyzes and both live judges (each case
    a false FAIL of the live judges once: ``FALSE_FAILS``' notes)."""
    spec = FALSE_FAILS[name][0]
    log = tmp_path / "drive.log"
    watch, code = _drive(spec, robots, log)
    _assert_right(watch)
    codes, beyond = _judged(log, robots[spec[0]])
    assert [code, *codes, *(b > 1e-4 for b in beyond)] == [0, 0, 0, False, False], beyond


def test_every_judge_right_both_ways_after_a_halt_on_slow16(robots: dict[str, str],
                                                            tmp_path: Path) -> None:
    """``SLOW16_LIVE`` (fixed): the live judges hold the encoder frames after the MCU's halt
    for its poses (``e2e_halts``) and choose at the second hole (``livesecond``) as analyze
    does: every judge PASSes the correct firmware (``FALSE_FAILS``) and FAILs X raised 10 mm
    from mid-drive on."""
    assert _both_ways(SLOW16, robots, tmp_path) == RIGHT


def test_c_firmware_writes_the_python_log_on_a_32_bit_robot(robots: dict[str, str],
                                                            tmp_path: Path) -> None:
    """The C firmware on a custom 32-bit-counter profile under a bus-off and duplicates: the
    same bytes as the Python firmware (so the same verdicts, which PASS)."""
    require_executables("make", "cc", install="apt-get install gcc make")
    cboard.load_library()
    argv = ["run", "--robot", robots["c32"], "--scenario", "circle", "--seed", "38",
            "--duration", "10", "--faults", "busoff=6.0:0.1,dup=0.05"]
    logs = [tmp_path / f"{fw}.log" for fw in ("python", "c")]
    codes = [main([*argv, "--firmware", fw, "--log", str(log)])
             for fw, log in zip(("python", "c"), logs, strict=True)]
    assert codes == [0, 0]
    assert logs[0].read_bytes() == logs[1].read_bytes()
