"""A reboot inside a bus silence (issue #11, HIGH): the new firmware's power-up is hidden, the
first summary heard says UPTIME 1, and its first count page (ENC_E2E_OK) names the encoder
frame it primed on (the first after the silence).

``reboots.split_lives`` (and ``stream_lives``) took the life's start from that page but judged it
as a log that starts mid-drive (``boot`` only for UPTIME 0): its start fitted, a firmware whose
X was 10 mm off over the whole new life PASSed ``analyze``, whole and streamed, the summary
saying "restarted at 7.10 s (fitted)" (trial 23b: ``--seed 31 --faults busoff=5:2,
reboot=5.5:0.3``). A new firmware starts at (0, 0, 0) by definition: a start its count page
names is a power-up, re-checked on the life (``powerup.saw_only_the_log``).

The tamper is the trial's (ODOM_POSE_X raised by 100 LSB, E2E CRC recomputed,
``tests.log_edit.raise_raw``); the correct firmware's PASS is the CLI's own run.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from odocan.host.cli.app import main
from tests.judges_cli import raise_x_10_mm

FROM_S = 6.0  # before the new life's first frame (the silence ends at busoff's end)
DRIVES = [  # (seed, faults): a reboot inside bus-offs of 1..3 s
    (31, "busoff=5:2,reboot=5.5:0.3"),
    (31, "busoff=5:2,reboot=5.5"),
    (7, "busoff=5:3,reboot=6:0.3"),
    (12, "busoff=5:2,reboot=5.5:0.3"),
]


def _run(path: Path, seed: int, faults: str) -> int:
    return main(["run", "--duration", "10", "--seed", str(seed), "--faults", faults,
                 "--log", str(path)])


@pytest.mark.parametrize(("seed", "faults"), DRIVES)
def test_a_reboot_in_a_silence_is_judged_from_its_power_up(
        seed: int, faults: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log, tampered = tmp_path / "drive.log", tmp_path / "tampered.log"
    assert _run(log, seed, faults) == 0
    capsys.readouterr()
    assert main(["analyze", str(log)]) == 0
    assert "(power-up)" in capsys.readouterr().out  # not "(fitted)"
    assert main(["analyze", str(log), "--stream", "always"]) == 0
    assert raise_x_10_mm(log, tampered, FROM_S) > 50
    capsys.readouterr()
    for stream in ("always", "never"):
        assert main(["analyze", str(tampered), "--stream", stream]) == 1
