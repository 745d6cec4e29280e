"""``tests.sweeps.sample``: a default run's share of a grid is fixed, keeps its pins, is never
empty, mixes the grid's axes; ``ODOCAN_SWEEPS=full`` keeps every case."""

from __future__ import annotations

import itertools
import subprocess
import sys

import pytest

from tests import sweeps
from tests.sweeps import sample

GRID = list(itertools.product(("spin", "square", "figure8", "circle"), (400, 500, 600, 800),
                              (2, 3, 4, 6)))


@pytest.fixture(autouse=True)
def _default_run(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(sweeps.SWEEPS_ENV, raising=False)


def test_a_share_of_the_grid_in_its_order_with_its_pins() -> None:
    pins = [("circle", 800, 2), ("spin", 400, 3)]
    kept = sample(GRID, 4, pins)
    assert set(pins) <= set(kept)
    assert kept == [case for case in GRID if case in kept]  # the grid's order
    assert len(GRID) // 8 < len(kept) < len(GRID) // 2, len(kept)
    for axis in range(3):  # no axis reduced to some of its values
        assert {case[axis] for case in kept} == {case[axis] for case in GRID}, axis


def test_the_share_is_the_same_in_another_process() -> None:
    code = ("import itertools; from tests.sweeps import sample; print(sample(itertools.product("
            "('spin', 'square', 'figure8', 'circle'), (400, 500, 600, 800), (2, 3, 4, 6)), 4))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True, env={"PYTHONHASHSEED": "123", "PATH": ""})
    assert done.stdout.strip() == repr(sample(GRID, 4))


def test_never_empty() -> None:
    assert sample([("only",)], 1_000_000) == [("only",)]
    assert len(sample(range(3), 1_000_000)) == 1


def test_full_keeps_every_case(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(sweeps.SWEEPS_ENV, "full")
    assert sample(GRID, 4) == GRID
    assert "every case" in sweeps.header()
