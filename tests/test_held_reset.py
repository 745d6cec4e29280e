"""A frame held back 150 ms that the firmware's E2E check took and its plausibility bound refused
is no E2E skip (issue #11: a FAIL must never blame a correct firmware, a PASS never hide a wrong
pose; ``host.protocol.e2e_skipveto``).

kobuki random, seed 710, ``busoff=1.5:0.4,delay=0.2:150,reboot=4.0:0.2``: at 7.26 and 7.28 s the
late WHEEL_ENCODERS COUNTER 7 and 9 came as the next in the sequence; the firmware's E2E check
took them, its plausibility bound refused them (the on-time 6 named held by the poses), and with
the late 12 three refusals in a row re-primed it on the late stream (and again at 7.37 s on the
on-time one). The host read the held name as E2E skips, took the on-time frames instead, saw
two re-primes fewer (7 where the firmware made 9) and FAILed the correct firmware in run and both
analyses by 2.34 mm and 107 mrad; the live judge was 20.0 mm beyond its allowance; replay said
"the log's poses fit no known robot profile". The firmware's ENC_E2E_OK pages say which reading
is right: the stamps' strict one met its count exactly in both spans, the poses' one took a
frame too many in each.
"""

from __future__ import annotations

from pathlib import Path

import can
import numpy as np
import pytest

from odocan.host.judge.monitor import BusMonitor
from odocan.host.protocol.e2e_evidence import S_LOST, S_OK, S_WRONG, Evidence
from odocan.host.protocol.e2e_pages import OkPages
from odocan.host.protocol.e2e_skipveto import by_page_skips, exact_surplus
from odocan.sim.robot import load
from tests.fw_watch import Watch
from tests.judges_cli import STREAMS, analyze, cli, raise_x_10_mm, watched_run, x_10_mm_off_fails

ROBOT, SCENARIO, SEED, DURATION_S = "kobuki", "random", 710, 9
FAULTS = "busoff=1.5:0.4,delay=0.2:150,reboot=4.0:0.2"
AFTER_FAULT_S = 4.5  # after the bus-off and the reboot (the delays last the whole drive)
Drive = tuple[Path, Watch, int]


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> Drive:
    log = tmp_path_factory.mktemp("held_reset") / "drive.log"
    watch, code = watched_run(log, ROBOT, SCENARIO, SEED, DURATION_S, FAULTS)
    return log, watch, code


def _live_beyond_m(log: Path) -> float:
    """The monitor's judge fed ``log`` frame by frame: its position error beyond its allowance."""
    monitor = BusMonitor(load(ROBOT))
    with can.LogReader(str(log)) as reader:
        for msg in reader:
            monitor.feed(msg, now_s=msg.timestamp)
    return monitor.tracker.max_beyond_allowance_m


def test_the_firmware_integrates_the_frames_it_took(drive: Drive) -> None:
    _, watch, _ = drive
    assert watch.steps > 300, watch.steps
    assert watch.within_a_thousandth_lsb(), (watch.worst_m, watch.worst_rad)


def test_run_and_both_analyzes_pass_the_correct_firmware(
        drive: Drive, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log, _, code = drive
    codes = [code, *(analyze(log, s, tmp_path / f"{s}.json") for s in STREAMS)]
    out = capsys.readouterr().out
    assert codes == [0, 0, 0], out[-2500:]


def test_the_live_judge_passes_the_correct_firmware(drive: Drive) -> None:
    """Within the 0.1 mm tolerance (20.0 mm beyond before)."""
    log, _, _ = drive
    beyond_m = _live_beyond_m(log)
    assert beyond_m <= 1e-4, beyond_m


def test_replay_finds_the_log_s_robot_and_passes(drive: Drive) -> None:
    """replay names the profile the poses fit (before: "fit no known robot profile", the
    analysis of the fit FAILed) and, since late poses are named from where they were sent
    (``replay_late``: a frame 150 ms late is 8 sends short of a lap), replays the reboot and the
    late frames: PASS (before, FAIL: "the log fits robot 'kobuki' ... its firmware lived what a
    lockstep replay does not reproduce")."""
    log, _, _ = drive
    done = cli("replay", str(log))
    out = done.stdout
    assert "fit no known robot profile" not in out, out[-1500:]
    assert f"on {ROBOT}, exact integrator" in out, out[:500]
    assert done.returncode == 0, out[-1500:]


@pytest.mark.parametrize("stream", STREAMS)
def test_plus_10_mm_after_the_faults_fails_by_the_position(
        drive: Drive, stream: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log, _, _ = drive
    wrong = x_10_mm_off_fails(log, tmp_path / "t.log", AFTER_FAULT_S, 50)
    capsys.readouterr()
    assert [w for w in wrong if w.startswith(f"--stream {stream}")] == []


def test_plus_10_mm_after_the_faults_fails_the_live_judge(drive: Drive, tmp_path: Path) -> None:
    log, _, _ = drive
    tampered = tmp_path / "t.log"
    assert raise_x_10_mm(log, tampered, AFTER_FAULT_S) > 50
    assert _live_beyond_m(tampered) > 5e-3


# --- the rule on hand-made verdicts ---------------------------------------------------------

# 8 encoder frames at bus positions 1..8; pages at 0 (count 0) and 9 (count 6)
ENC_POS = np.arange(1, 9, dtype=np.intp)
PAGES = OkPages(np.array([0, 9], dtype=np.intp), np.array([0, 6], dtype=np.int64))
OK, LOST, WRONG = S_OK, S_LOST, S_WRONG


def _statuses(*codes: int) -> np.ndarray:
    return np.array(codes, dtype=np.int8)


def test_exact_surplus_counts_without_a_race() -> None:
    seven = _statuses(OK, OK, OK, OK, LOST, OK, OK, WRONG)
    assert exact_surplus(ENC_POS, seven, PAGES).tolist() == [1]
    six = _statuses(OK, OK, WRONG, OK, LOST, OK, OK, WRONG)
    assert exact_surplus(ENC_POS, six, PAGES).tolist() == [0]


def test_skips_are_dropped_only_where_that_meets_the_count() -> None:
    strict = _statuses(OK, OK, WRONG, OK, LOST, OK, OK, WRONG)  # 6: the firmware's count
    settled = _statuses(OK, OK, OK, OK, LOST, OK, OK, WRONG)  # 7: a skip read as E2E's
    evidence = Evidence(frozenset(), frozenset({3}))
    seen: list[Evidence] = []

    def meets(proofs: Evidence) -> np.ndarray:
        seen.append(proofs)
        return strict

    def misses(proofs: Evidence) -> np.ndarray:
        return _statuses(OK, OK, OK, OK, OK, OK, OK, WRONG)  # 7 again: not kept

    assert by_page_skips(meets, settled, strict, ENC_POS, evidence, PAGES).tolist() == (
        strict.tolist())
    assert seen == [Evidence(frozenset(), frozenset())]
    assert by_page_skips(misses, settled, strict, ENC_POS, evidence, PAGES) is settled
    # the strict reading off the count too: the skips stand
    assert by_page_skips(meets, settled, settled, ENC_POS, evidence, PAGES) is settled
    assert by_page_skips(meets, settled, strict, ENC_POS, evidence, None) is settled
