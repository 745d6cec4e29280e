"""Frames late on the bus (``--faults delay``: reordered) never flip a verdict (issue #11, rule 5).

An outside trial found, on 10 to 20 s kobuki drives: ``run`` PASS but ``analyze`` of its
``.log`` FAIL (227 mrad), the ``.blf`` of the same drive PASS (223 times 1 ns apart); ``run``
FAIL (365 mrad) on a firmware an independent checker found right; ``analyze`` of a ``.blf``
FAIL where ``run`` PASSed. The cause: the host's model of the firmware's E2E window counted the
periods between an encoder frame and one 15 ms late (half a period off its slot) by rounding
half to even, so 1 ns of timestamp decided whether the firmware's window had widened; the two
then disagreed on which encoder frames the firmware had taken, and a pose was paired with a
frame 16 periods away. And the rig wrote a frame held back by ``delay`` after frames later than
it (times going back in its log).

Here, on the trial's three drives: the log is in bus order; ``run``, the whole-log ``analyze``,
the streamed ``analyze`` (the CLI's) and the live judge (the monitor model) PASS in every log
format; the same drives by a firmware whose pose is off by 2 LSB (X or HEADING) FAIL in all of
them; and no verdict changes when every timestamp is moved by up to 1 us.
"""

from __future__ import annotations

import itertools
import json
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path

import can
import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

import odocan.firmware.frames as fw_frames
from odocan.firmware.errors import ErrorMask
from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from odocan.host.judge.monitor import BusMonitor
from odocan.sim.robot import load
from tests.sweeps import sample
from tests.test_powerup_delay import _live_passes, first_count_page

# (duration s, seed or None: the default, faults) of the trial's reproductions
DRIVES = [
    (10, 2, "delay=0.1:15,seed=2"),
    (10, 2, "delay=0.1:25,seed=2"),
    (20, None, "delay=0.05:25,seed=4"),
]
FORMATS = (".log", ".blf", ".asc")
KOBUKI = load("kobuki")
# tests.sweeps: every drive as a .log, the first as each format, and one in three of the rest
FORMATTED = sample(itertools.product(DRIVES, FORMATS), 3,
                   [(d, ".log") for d in DRIVES] + [(DRIVES[0], f) for f in FORMATS])
WRONG = sample(itertools.product(DRIVES, FORMATS, ["X", "HEADING"]), 3,
               [(d, ".log", "X") for d in DRIVES] + [(DRIVES[2], ".blf", "HEADING")])


@contextmanager
def _off_by_two(signal: str | None) -> Iterator[None]:
    """The Python firmware with its ODOM_POSE_X ``X`` or ``HEADING`` 2 LSB off (None: right)."""
    if signal is None:
        yield
        return
    right = fw_frames.pack_odom_pose_x

    def wrong(counter: int, enc_counter: int, x_100um: int, heading_bam16: int,
              errors: ErrorMask) -> bytes:
        return right(counter, enc_counter, x_100um + 2 * (signal == "X"),
                     heading_bam16 + 2 * (signal == "HEADING"), errors)

    with pytest.MonkeyPatch.context() as monkeypatch:
        monkeypatch.setattr(fw_frames, "pack_odom_pose_x", wrong)
        yield


def _run(path: Path, drive: tuple[int, int | None, str], wrong: str | None) -> int:
    duration, seed, faults = drive
    argv = ["run", "--robot", "kobuki", "--duration", str(duration), "--faults", faults,
            "--log", str(path), "--firmware", "python"]  # the patched Python firmware, never C
    argv += ["--seed", str(seed)] if seed is not None else []
    with _off_by_two(wrong):
        return main(argv)


def _verdicts(path: Path, run_code: int) -> dict[str, bool]:
    return {
        "run": run_code == 0,
        "analyze (streamed, CLI)": main(["analyze", str(path), "--robot", "kobuki"]) == 0,
        "analyze (whole log)": analyze(read_log(path), KOBUKI).passed,
        "live": _live_passes(path),
    }


@pytest.mark.parametrize(("drive", "fmt"), FORMATTED, ids=[f"{d[2]}{f}" for d, f in FORMATTED])
def test_a_delayed_drive_passes_everywhere(
    tmp_path: Path, drive: tuple[int, int | None, str], fmt: str
) -> None:
    path = tmp_path / f"drive{fmt}"
    verdicts = _verdicts(path, _run(path, drive, None))
    assert all(verdicts.values()), verdicts


@pytest.mark.parametrize(("drive", "fmt", "wrong"), WRONG,
                         ids=[f"{d[2]}{f}-{w}" for d, f, w in WRONG])
def test_a_pose_two_lsb_off_fails_everywhere(
    tmp_path: Path, drive: tuple[int, int | None, str], fmt: str, wrong: str
) -> None:
    path = tmp_path / f"drive{fmt}"
    verdicts = _verdicts(path, _run(path, drive, wrong))
    assert not any(verdicts.values()), verdicts


@pytest.mark.parametrize("drive", [DRIVES[1], (4, 703, "delay=0.1:20,seed=703"),
                                   (4, 703, "delay=0.2:30,seed=703")], ids=lambda d: d[2])
@pytest.mark.parametrize("fmt", FORMATS)
def test_the_rigs_log_is_in_bus_order(
    tmp_path: Path, fmt: str, drive: tuple[int, int | None, str]
) -> None:
    """A frame held back goes on the bus at its release time, before anything sent later; one
    held a whole number of periods too (due at 0.30000000000000004 s, it went out a tick late,
    after the firmware's frames of 0.301 s)."""
    path = tmp_path / f"drive{fmt}"
    assert _run(path, drive, None) == 0
    times = read_log(path).timestamp_s
    assert np.all(np.diff(times) >= 0), int(np.count_nonzero(np.diff(times) < 0))


@contextmanager
def _distance_off(mm: int) -> Iterator[None]:
    """The Python firmware with its ODOM_TWIST ``DISTANCE`` ``mm`` off (0: right)."""
    right = fw_frames.pack_odom_twist

    def wrong(counter: int, enc_counter: int, linear_vel_mm_s: int, angular_vel_mrad_s: int,
              distance_mm: int, errors: ErrorMask) -> bytes:
        return right(counter, enc_counter, linear_vel_mm_s, angular_vel_mrad_s,
                     distance_mm + mm, errors)

    with pytest.MonkeyPatch.context() as monkeypatch:
        monkeypatch.setattr(fw_frames, "pack_odom_twist", wrong)
        yield


def _live_distance_passes(path: Path) -> bool:
    """The monitor model's DISTANCE verdict (``livedistance``)."""
    monitor = BusMonitor(KOBUKI)
    with can.LogReader(path) as reader:
        for msg in reader:
            monitor.feed(msg, now_s=msg.timestamp)
    return not monitor.distance.verdict()


# the drive whose first count page came late (``test_a_late_first_status_page_...``)
LATE_PAGE = (4, 48, "delay=0.05:10,seed=48")


@pytest.mark.parametrize("off_mm", [0, 1, 2])
@pytest.mark.parametrize("drive", [*DRIVES, LATE_PAGE], ids=[d[2] for d in [*DRIVES, LATE_PAGE]])
def test_distance_under_delays_passes_right_and_fails_off_by_a_mm(
    tmp_path: Path, drive: tuple[int, int | None, str], off_mm: int
) -> None:
    """DISTANCE under the trial's delays: a right firmware's PASSes in run, the streamed and
    the whole-log analyze and the live judge (the first failed in all but live: a twist naming
    by its repeated ENC_COUNTER a frame 16 periods before the one it carried was judged); one
    1 or 2 mm off FAILs in all four (``LATE_PAGE``: 1 mm off PASSed in all four, its first
    count page taken for a cut log's). Checked against the report's own DISTANCE verdict, so
    the pose's verdict does not mask it."""
    path = tmp_path / "drive.blf"
    duration, seed, faults = drive
    argv = ["run", "--robot", "kobuki", "--duration", str(duration), "--faults", faults,
            "--log", str(path), "--firmware", "python"] + (
                ["--seed", str(seed)] if seed is not None else [])
    with _distance_off(off_mm):
        code = main(argv)
    report = tmp_path / "report.json"
    main(["analyze", str(path), "--robot", "kobuki", "--report", str(report)])
    whole = analyze(read_log(path), KOBUKI).report["onboard_distance_vs_reference"]
    verdicts = {
        "run": code == 0,
        "analyze (streamed, CLI)": json.loads(report.read_text())[
            "onboard_distance_vs_reference"]["passed"],
        "analyze (whole log)": whole["passed"],
        "live": _live_distance_passes(path),
    }
    assert whole["samples"] > 0
    assert all(verdicts.values()) if off_mm == 0 else not any(verdicts.values()), verdicts


# Delays in whole ms, not 1 ms past a 10 ms boundary: that lands an encoder frame exactly on the
# firmware's tick (1 ms after the slot in the rig), the one edge the firmware has too
# (``host.protocol.e2e_periods.receive_periods``), where 1 us decides what it took.
DELAYS_MS = [d for d in range(2, 40) if d % 10 != 1]


@settings(max_examples=8, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 1000), delay_ms=st.sampled_from(DELAYS_MS),
       share=st.sampled_from([0.05, 0.1, 0.2]), wrong=st.sampled_from([None, "X", "HEADING"]),
       jitter_seed=st.integers(0, 2**32 - 1), duration_s=st.just(4))
@example(seed=2, delay_ms=15, share=0.1, wrong=None, jitter_seed=1, duration_s=10)
@example(seed=2, delay_ms=25, share=0.1, wrong=None, jitter_seed=2, duration_s=10)
def test_a_microsecond_never_flips_the_verdict(
    tmp_path: Path, seed: int, delay_ms: int, share: float, wrong: str | None, jitter_seed: int,
    duration_s: int,
) -> None:
    """Every timestamp moved by up to 1 us: the same verdict, whole log and streamed alike; a
    right firmware PASSes. (That a wrong one FAILs: ``test_powerup_delay``, drawn the same way.)
    Drawn: 4 s drives; the examples: two of the trial's 10 s drives (they failed before)."""
    path = tmp_path / f"d{seed}_{delay_ms}_{share}_{wrong}.blf"
    code = _run(path, (duration_s, seed, f"delay={share}:{delay_ms},seed={seed}"), wrong)
    frames = read_log(path)
    jitter = np.random.default_rng(jitter_seed).uniform(-1e-6, 1e-6, len(frames))
    moved = replace(frames, timestamp_s=frames.timestamp_s + jitter)
    report = tmp_path / "report.json"
    main(["analyze", str(path), "--robot", "kobuki", "--report", str(report)])
    verdicts = {"run": code == 0, "whole": analyze(frames, KOBUKI).passed,
                "streamed": json.loads(report.read_text())["passed"],
                "whole, 1 us moved": analyze(moved, KOBUKI).passed}
    assert len(set(verdicts.values())) == 1, verdicts
    if wrong is None:
        assert verdicts["run"], verdicts


def test_a_late_first_status_page_still_tells_the_power_up(tmp_path: Path) -> None:
    """Found by the test above: 4 s, ``delay=0.05:10,seed=48``, a firmware whose X is 2 LSB off
    PASSed. Its first ENC_E2E_OK page, made at 0.101 s with 11 encoder frames counted (as many as
    were before the summary sent in its tick), was held 10 ms and reached the bus after the 12th,
    so the judges took the log for one that does not start at power-up, and the start fitted to
    the samples took the constant offset in. Now they count the frames on the bus when the page
    was made (``powerup.made_at``): the wrong firmware FAILs everywhere, the right one PASSes
    (more drives: ``test_powerup_delay``)."""
    right, wrong = tmp_path / "right.blf", tmp_path / "wrong.blf"
    drive = LATE_PAGE
    assert _run(right, drive, None) == 0
    assert first_count_page(right) == (11, 11, 12)
    assert all(_verdicts(right, 0).values())
    verdicts = _verdicts(wrong, _run(wrong, drive, "X"))
    assert not any(verdicts.values()), verdicts


def test_frames_held_two_periods_pass_a_right_firmware(tmp_path: Path) -> None:
    """Found by the drawn property above after the session's merges (seed 703, 10 % of frames
    held 20 ms, 4 s): run FAILed our own firmware, whole and streamed alike (heading 22 mrad,
    DISTANCE 95 mm). The rig put a frame due at 0.28 + 0.02 = 0.30000000000000004 s on the bus a
    tick late, after its log time (tests/test_held_frames.py tells the whole story)."""
    assert _run(tmp_path / "d703.blf", (4, 703, "delay=0.1:20,seed=703"), None) == 0


# Delays of 5..40 ms, whole periods among them (10, 20, 30: a frame due on a tick's start), not
# 1 ms past a 10 ms boundary (the firmware's own tick: the edge above).
HELD_MS = [d for d in range(5, 41) if d % 10 != 1]


@settings(max_examples=4, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 1000), delay_ms=st.sampled_from(HELD_MS),
       share=st.sampled_from([0.1, 0.2]))
@example(seed=703, delay_ms=20, share=0.1)
@example(seed=703, delay_ms=20, share=0.2)
@example(seed=703, delay_ms=30, share=0.2)
@example(seed=1, delay_ms=40, share=0.2)
@example(seed=305, delay_ms=17, share=0.1)
def test_held_frames_pass_a_right_firmware(
    tmp_path: Path, seed: int, delay_ms: int, share: float
) -> None:
    """4 s drives with frames held 5..40 ms: a right firmware PASSes in run, the whole-log and
    the streamed analyze and the live judge. The first four examples FAILed before the rig put
    the frames due by the firmware's tick on the bus before it (one held 20 ms from 0.28 s is
    due at 0.30000000000000004 s); the last is the draw that found the open case below."""
    path = tmp_path / "held.blf"
    verdicts = _verdicts(path, _run(path, (4, seed, f"delay={share}:{delay_ms},seed={seed}"), None))
    assert all(verdicts.values()), verdicts


@settings(max_examples=4, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(seed=st.sampled_from([305, 703]), delay_ms=st.sampled_from(HELD_MS),
       share=st.sampled_from([0.1, 0.2]))
@example(seed=305, delay_ms=17, share=0.1)
@example(seed=305, delay_ms=40, share=0.1)
@example(seed=703, delay_ms=20, share=0.1)
@example(seed=703, delay_ms=30, share=0.2)
@example(seed=1, delay_ms=40, share=0.2)
@example(seed=42, delay_ms=15, share=0.1)
@example(seed=1, delay_ms=5, share=0.2)
@example(seed=703, delay_ms=10, share=0.2)
def test_held_frames_fail_a_pose_two_lsb_off(
    tmp_path: Path, seed: int, delay_ms: int, share: float
) -> None:
    """The same drives by a firmware whose X is 2 LSB off FAIL in all four; the draws sweep the
    delays on the two seeds whose drives lock the firmware out most (other seeds: the last four
    examples; a draw whose start the judges fit, not proven at power-up, may absorb a constant
    offset: seed 670, ``delay=0.2:24``, ``test_powerup_delay``'s business). The first two
    examples were reported to PASS run, the whole-log and the streamed analyze (the live judge
    FAILed them); on this branch's base they FAIL already (the constant offset shows before the
    first lock-out): ``test_lockout_fill`` shows the gaps' allowance itself:
    the firmware refuses the on-time frame that follows a late one it took (its window, reset
    to 0 on the late frame, widens one a tick while the COUNTER runs one a tick ahead), and so
    every frame until its COUNTER comes round: up to 16 periods on one pose (``delay=0.1:20``
    on seed 703: 176 of 400 encoder frames refused). ``gapfill`` placed those refused frames
    from the last accepted frame, the late one, so their COUNTER fell 16 periods back and the
    judges kept ``gapbound``'s worst case for each such gap (seed 305, 20 ms: 35 gaps, 100.6 mm
    summed), which swallowed the offset although every frame of those gaps is on the log and
    their own E2E model refuses it as the firmware did. Now a refused frame is placed on the
    sender's grid (from the least late recent accepted frame): the gaps are filled."""
    path = tmp_path / "held.blf"
    verdicts = _verdicts(path, _run(path, (4, seed, f"delay={share}:{delay_ms},seed={seed}"), "X"))
    assert not any(verdicts.values()), verdicts


def test_lock_outs_do_not_absorb_a_pose_two_lsb_off(tmp_path: Path) -> None:
    """The case the draws above found (seed 305, frames held 20 ms, 4 s), kept by name: a
    firmware whose X is 2 LSB off FAILs run, the whole-log and the streamed analyze and the
    live judge; the same drive by the right firmware PASSes all four."""
    wrong, right = tmp_path / "wrong.blf", tmp_path / "right.blf"
    drive = (4, 305, "delay=0.1:20,seed=305")
    verdicts = _verdicts(wrong, _run(wrong, drive, "X"))
    assert not any(verdicts.values()), verdicts
    verdicts = _verdicts(right, _run(right, drive, None))
    assert all(verdicts.values()), verdicts
