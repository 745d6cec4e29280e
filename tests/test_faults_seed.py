"""The fault stream follows ``--seed`` unless the spec sets its own (issue #11's last note).

``run --seed N --faults babble=...`` drew its faults from seed 0 at every N (the spec's default),
so sweeping --seed swept the drive but never the babble: every run met one babble stream. Now
the spec's seed, when the text sets none, is the command's --seed; ``seed=`` in the text still
wins, and one --seed still gives the same bytes (lockstep determinism). Checked on the frames
of a babbling node on an ID nothing else sends (0x7F0), read back with python-can."""

from __future__ import annotations

import argparse
from pathlib import Path

import can
import pytest

from odocan.host.cli.app import main
from odocan.host.io.buses import parse_faults

QUIET_ID = 0x7F0  # not in the DBC: only the babbler sends on it


def test_the_spec_seed_defaults_to_the_commands_seed() -> None:
    def spec_seed(faults: str, **seed: int) -> int:
        spec = parse_faults(argparse.Namespace(faults=faults, **seed))
        assert spec is not None
        return spec.seed

    assert spec_seed("babble=100", seed=7) == 7
    assert spec_seed("babble=100,seed=2", seed=7) == 2  # the text's own seed wins
    assert spec_seed("drop=0.1") == 0  # a command without --seed (``firmware``)


def _babble(tmp_path: Path, seed: int, name: str) -> list[tuple[float, bytes]]:
    log = tmp_path / f"{name}.log"
    assert main(["run", "--duration", "1", "--seed", str(seed), "--faults",
                 f"babble=2000:0x{QUIET_ID:03X}", "--log", str(log)]) == 0
    with can.LogReader(str(log)) as reader:
        return [(m.timestamp, bytes(m.data)) for m in reader if m.arbitration_id == QUIET_ID]


def test_runs_at_two_seeds_babble_differently_and_one_seed_repeats(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    one, again, two = (_babble(tmp_path, 1, "one"), _babble(tmp_path, 1, "again"),
                       _babble(tmp_path, 2, "two"))
    capsys.readouterr()
    assert len(one) > 1000  # ~2000 frames in the second
    assert one == again
    assert [data for _, data in one] != [data for _, data in two]
