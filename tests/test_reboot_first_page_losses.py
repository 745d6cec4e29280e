"""A firmware that reboots and loses encoder frames before its first page of E2E counts: the
life starts at the frame it primed on (issue #11, rule 3: a FAIL must never blame a correct
firmware).

``host.judge.reboots`` finds that frame from the new firmware's first ODOM_STATUS page of
WHEEL_ENCODERS E2E counts: the firmware took every frame from it on, accepted (ENC_E2E_OK) or
lost (ENC_E2E_LOST: its mailbox dropped them, or the bus did). Counting ENC_E2E_OK frames back
from the page, as it did, lands as many frames late as it lost the bus carried; that count
overrode even the boot summary's exact frame, and the reference started there, at the
power-up pose, while the firmware had already moved: a correct kobuki FAILed by 12 mm (the
whole-log and the streamed ``analyze``, ``host.judge.stream_lives``, and the live judge, which
counted ENC_E2E_OK frames back in its window). The start is the frame ENC_E2E_OK +
ENC_E2E_LOST - 1 COUNTER steps back from the latest frame before the page
(``host.judge.primed.counted_start``, one rule for the three): the earliest the counts allow,
exact when the log holds it.

The logs are written directly (``tests/synth_log.py``: the firmware's own odometry and codec,
the frames it lost not integrated, its next step merged); the verdicts are checked against
``tests/independent_checker.py`` (float64 odometry, cantools), never against host code.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from odocan.host.judge.reboots import split_lives
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.protocol.decode import BulkDecoder
from odocan.sim.robot import load
from tests.synth_log import Synth, synthesize, wandering_drive
from tests.test_analysis_reboot import REBOOT, STEPS, independent
from tests.test_capture_jitter import _live_passes

LOST = {REBOOT + 3, REBOOT + 4}  # dropped by the new firmware's mailbox, before its first page


def _drive(bias_100um: int, keep_boot_summary: bool) -> Synth:
    profile = load("kobuki")
    d_left, d_right = wandering_drive(profile, STEPS, 0.004, seed=7)
    bias = {k: bias_100um for k in range(REBOOT, STEPS + 1)}
    synth = synthesize(profile, "exact", d_left, d_right, reboot_at=REBOOT, x_bias_100um=bias,
                       firmware_lost=LOST)
    if not keep_boot_summary:  # the recorder lost it: the page alone names the frame
        synth.groups[REBOOT] = [line for line in synth.groups[REBOOT]
                                if " 380#" not in line.upper()]
    return synth


@pytest.mark.parametrize("keep_boot_summary", [True, False])
def test_the_life_starts_at_the_frame_the_firmware_primed_on(
    tmp_path: Path, keep_boot_summary: bool
) -> None:
    """Before: two frames late (the encoder frame REBOOT + 2)."""
    path = _drive(0, keep_boot_summary).write(tmp_path / "reboot.log")
    frames = read_log(path)
    decoder = BulkDecoder(default_plan())
    lives = split_lives(frames, decoder)
    assert len(lives) == 2
    encoders = decoder.decode(frames, "WHEEL_ENCODERS")["index"]
    assert int(lives[1].index[0]) == int(encoders[REBOOT])


@pytest.mark.parametrize("keep_boot_summary", [True, False])
@pytest.mark.parametrize("bias_100um", [0, 2])
def test_the_verdict_follows_the_independent_checker(
    tmp_path: Path, keep_boot_summary: bool, bias_100um: int,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Before: the correct firmware FAILed (12 mm), whole, streamed and live. The drive has
    no ODOM_TWIST: the CLI's verdict on the right pose is UNJUDGED (host.judge.verdictfacts)."""
    profile = load("kobuki")
    path = _drive(bias_100um, keep_boot_summary).write(tmp_path / "reboot.log")
    assert independent(path, profile, "exact", REBOOT) == (bias_100um == 0)
    analysis = analyze(read_log(path), profile)
    assert analysis.passed == (bias_100um == 0), analysis.report["onboard_vs_reference"]
    assert analysis.report["reboots"][0]["reference_start"] == "power-up"
    capsys.readouterr()
    streamed = main(["analyze", str(path), "--robot", "kobuki", "--stream", "always"])
    verdict = capsys.readouterr().out.strip().splitlines()[-1]
    assert streamed == 1, verdict
    assert verdict.startswith("UNJUDGED: no ODOM_TWIST" if bias_100um == 0 else "FAIL"), verdict
    assert _live_passes(path, "kobuki") == (bias_100um == 0)  # the monitor's model
