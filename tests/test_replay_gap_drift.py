"""`odocan replay` of a log with gaps: a departing firmware must FAIL after the first gap too.

Found by the trial: replay compares the replayed positions with the logged ones only up to the
log's first gap of the encoder sequence (across a gap the recording firmware may have had frames
the log lacks). A drive with lost encoder frames (`--faults drop=0.1`) has its first gap within
the first tenth of a second, so replaying it with another integrator than the one that recorded it
printed "max difference 3.9217 mm" and PASS, exit 0 — the departure the replay exists to catch.
Between two gaps both firmwares take the same frames from the same (exact) heading, so one
firmware's positions keep their offset from the log's there (within one LSB of rounding); a
recorder hole in a clean log (the firmware had the frames the log lacks: its positions are up to
3.3 mm off the replay's after the hole) must still PASS.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from odocan.host.cli.app import main


@pytest.fixture(scope="module")
def dropped_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 10 s kobuki drive (exact integrator) that lost 10 % of its encoder frames on the bus."""
    log = tmp_path_factory.mktemp("gapdrift") / "drop.log"
    assert main(["run", "--robot", "kobuki", "--duration", "10", "--seed", "2",
                 "--faults", "drop=0.1,seed=3", "--log", str(log)]) == 0
    return log


def test_another_integrator_departs_after_the_first_gap_the_same_firmware_not(
    dropped_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    capsys.readouterr()
    assert main(["replay", str(dropped_log), "--robot", "kobuki", "--integrator", "euler"]) == 1
    out = capsys.readouterr().out
    assert "between gaps of the log its position moves off the log's by up to" in out
    # and never the firmware that recorded it: with gaps, and with holes of the recorder's
    assert main(["replay", str(dropped_log), "--robot", "kobuki"]) == 0
    clean = tmp_path / "clean.log"
    assert main(["run", "--robot", "kobuki", "--duration", "10", "--seed", "2",
                 "--log", str(clean)]) == 0
    lines = clean.read_text().splitlines(keepends=True)
    for start in (500, 1200, 2000, 2800):  # 150 lines (~0.2 s) the recorder lost, not the
        holed = tmp_path / f"hole{start}.log"  # firmware: its positions are mm off the
        holed.write_text("".join(lines[:start] + lines[start + 150:]))  # replay's after it
        capsys.readouterr()
        assert main(["replay", str(holed), "--robot", "kobuki"]) == 0, capsys.readouterr().out
