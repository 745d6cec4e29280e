"""A long stall under a bus that holds frames back 150 ms (issue #11, rule 5), found by an
outside trial: kobuki circle seed 7163, 30 s, ``delay=0.1:150,stall=8:2`` FAILed a correct
firmware by 1836.6 mm and 3889 mrad, with two reboots that never happened ("restarted at
18.05 s (power-up), 23.05 s (fitted)"): ODOM_STATUS summaries held back behind newer ones read
as UPTIME going back (fixed with ``host.judge.livelatestatus``; ``tests/test_late_status.py``
has the rule's own tests). It PASSed then (no reboot told), and the same log with a pose
10 mm off from the stall's start, or from after it, FAILs (the edit made with cantools,
``tests.log_edit``). Since lone pose halves are judged (``lonehalves``) the correct firmware
FAILs again, 3.43 mm, on them: a strict xfail below."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from tests.log_edit import raise_raw

TAMPER_LSB = 100  # 10 mm in ODOM_POSE_X's 0.1 mm LSBs
Drive = tuple[Path, subprocess.CompletedProcess[str]]  # the log, run's outcome


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    done = subprocess.run([sys.executable, "-m", "odocan", *args], capture_output=True,
                          text=True, timeout=900, check=False)
    assert "Traceback" not in done.stderr, done.stderr
    return done


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> Drive:
    log = tmp_path_factory.mktemp("delaystall") / "d.log"
    done = _cli("run", "--robot", "kobuki", "--scenario", "circle", "--seed", "7163",
                "--duration", "30", "--faults", "delay=0.1:150,stall=8:2", "--log", str(log))
    return log, done


@pytest.mark.xfail(strict=True, reason=(
    "issue #11: since the lone pose halves are judged (lonehalves, merged after this drive was "
    "fixed): its 239 lone halves judged put the correct firmware 3.43 mm beyond the allowance "
    "(max_position_error_beyond_allowance_m; the pairs 0.0671 mm, within); no reboot told. A "
    "150 ms delay holds a pose frame back 15 periods, about a lap of its 4-bit ENC_COUNTER: the "
    "half's frame is likely named one lap off (not traced); 40 logs of 11 fault mixes, the "
    "delay=0.5:150 ones included, keep their verdicts"))
def test_the_correct_firmware_passes_with_no_reboot_told(drive: Drive) -> None:
    log, done = drive
    assert done.returncode == 0, done.stdout[-3000:]
    assert "restarted at" not in done.stdout, done.stdout[-3000:]
    for stream in ("never", "always"):
        assert _cli("analyze", str(log), "--robot", "kobuki", "--stream", stream).returncode == 0


@pytest.mark.parametrize("from_s", [8.0, 12.0])
def test_a_pose_10_mm_off_fails(drive: Drive, from_s: float, tmp_path: Path) -> None:
    log, _ = drive
    tampered = tmp_path / "t.log"
    assert raise_raw(log, tampered, "ODOM_POSE_X", (2, 4), TAMPER_LSB, from_s) > 100
    for stream in ("never", "always"):
        assert _cli("analyze", str(tampered), "--robot", "kobuki",
                    "--stream", stream).returncode == 1, stream
