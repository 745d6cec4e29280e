"""``odocan replay`` of a stalled firmware's log across where the stall falls (issue #11).

The replay halts each stall where the log's poses say and feeds its receive FIFO what the log
says the board held (``host.judge.replay_halts``): for every ``stall=T:DUR`` of a small grid
(T a tick or half a tick either side of 2 s, DUR from the board's threshold of 9 ticks to 20),
on an instant and a bit-timed bus, seeds 4..6 (a default run: the cases found below and a
third of the rest, ``tests.sweeps``), a correct firmware's replay is identical to its
log (exit 0), and the same log with ODOM_POSE_X raised 10 mm after the stall is refused (exit
1). Before: ``stall=2.015:0.105 -b 500000`` (seed 4) was replayed a tick early, departed by
20.26 mm and was UNJUDGED; ``stall=2.005:0.095`` a tick late, 1 LSB off at 13 of 294 poses.
And halts of 14 mod 16 ticks (30, 46, 62) from a pose tick: the first pose after the halt names
the encoder frame the FIFO held, of the same COUNTER as the frame 32 ticks later, where the
replay's comparison put it (``replay_track.EncoderTrack.named``) beside that frame's own pose:
UNJUDGED, 345.6 mrad "off", for a byte-identical replay of a correct firmware.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from odocan.host.cli.app import main
from tests.judges_cli import raise_x_10_mm
from tests.sweeps import sample

RUN_S = 2.6  # the stall's end (2.22 s at most) well before the run's
STARTS_S = (2.000, 2.005, 2.010, 2.015, 2.020)
DURATIONS_S = (0.095, 0.105, 0.2)


def _replayed(log: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, dict[str, object]]:
    """``odocan replay``'s exit code and its report's ``replay`` section."""
    report = log.with_suffix(".json")
    code = main(["replay", str(log), "--report", str(report)])
    capsys.readouterr()
    return code, json.loads(report.read_text())["replay"]


@pytest.mark.parametrize("bus", [[], ["-b", "500000"]], ids=["instant", "bit-timed"])
@pytest.mark.parametrize("seed", [4, 5, 6])
def test_every_stall_of_the_grid_is_replayed_identically_and_a_tamper_after_it_fails(
    seed: int, bus: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    wrong: list[tuple[object, ...]] = []
    grid = [(seed, len(bus), at_s, dur_s) for at_s in STARTS_S for dur_s in DURATIONS_S]
    pins = [(4, 2, 2.015, 0.105), (4, 0, 2.005, 0.095), (4, 0, 2.0, 0.095)]  # found (docstring)
    for _, _, at_s, dur_s in sample(grid, 3, pins):  # tests.sweeps
        log = tmp_path / f"s{at_s}_{dur_s}.log"
        assert main(["run", "--duration", str(RUN_S), "--seed", str(seed), *bus,
                     "--faults", f"stall={at_s}:{dur_s}", "--log", str(log)]) == 0
        capsys.readouterr()
        code, replay = _replayed(log, capsys)
        vs = replay["onboard_vs_log"]
        assert isinstance(vs, dict)
        if code != 0 or vs["identical"] != vs["samples"] or vs["samples"] < 100:
            wrong.append((at_s, dur_s, code, vs["identical"], vs["samples"]))
        tampered = tmp_path / "tampered.log"
        assert raise_x_10_mm(log, tampered, at_s + dur_s + 0.05) > 5
        code, _ = _replayed(tampered, capsys)
        if code != 1:
            wrong.append((at_s, dur_s, "tampered", code))
    assert not wrong, wrong


HALTS_14_MOD_16_S = (0.3, 0.46, 0.62)  # 30, 46, 62 ticks


@pytest.mark.parametrize(("seed", "bus"), [(0, []), (5, []), (0, ["-b", "500000"]),
                                           (4, ["-b", "500000"])],
                         ids=["instant-0", "instant-5", "bit-timed-0", "bit-timed-4"])
def test_a_halt_of_14_mod_16_ticks_is_replayed_identically_and_a_tamper_after_it_fails(
    seed: int, bus: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    wrong: list[tuple[object, ...]] = []
    for dur_s in HALTS_14_MOD_16_S:
        log = tmp_path / f"h{dur_s}.log"
        assert main(["run", "--duration", str(2.9), "--seed", str(seed), *bus,
                     "--faults", f"stall=2:{dur_s}", "--log", str(log)]) == 0
        capsys.readouterr()
        code, replay = _replayed(log, capsys)
        vs = replay["onboard_vs_log"]
        assert isinstance(vs, dict)
        if code != 0 or vs["identical"] != vs["samples"] or vs["samples"] < 100:
            wrong.append((dur_s, code, vs["identical"], vs["samples"]))
        tampered = tmp_path / "tampered.log"
        assert raise_x_10_mm(log, tampered, 2 + dur_s + 0.05) > 5
        code, _ = _replayed(tampered, capsys)
        if code != 1:
            wrong.append((dur_s, "tampered", code))
    assert not wrong, wrong
