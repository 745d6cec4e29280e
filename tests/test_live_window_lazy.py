"""The live judge's window (``livewindow.Columns``) copies its rows into numpy only when a column
is read: a window never read (a pose half window, mostly) copies nothing however long it runs,
and a read copies once, the rows appended since the one before. Whatever the reads, a column is
the latest ``size`` rows appended, float64, as an independent float64 array of every row
appended gives them; ``rows`` the latest ``RECENT`` tuples, ``whole`` and ``len`` as before."""

from __future__ import annotations

import random

import numpy as np
import pytest

from odocan.host.judge import livewindow
from odocan.host.judge.livewindow import RECENT, Columns

NAMES = ("seq", "counter", "t_s")


def _row(k: int) -> tuple[int, int, float]:
    return k, (k * 7) & 0xF, 0.01 * k + 1e-9 * (k % 3)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_column_read_is_the_latest_rows_whatever_the_reads(seed: int) -> None:
    rng = random.Random(seed)
    size = 64
    window, appended = Columns(NAMES, size), []
    for k in range(20 * size):
        row = _row(k)
        window.append(*row)
        appended.append(row)
        if rng.random() < 0.05 or k in (0, size - 1, size, 2 * size + 3):
            expected = np.array(appended[-size:], dtype=np.float64)
            for i, name in enumerate(NAMES):
                column = window.col(name)
                assert column.dtype == np.float64
                assert np.array_equal(column, expected[:, i]), (k, name)
        assert len(window) == min(k + 1, size)
        assert list(window.rows) == appended[-RECENT:]
        assert window.whole == (k + 1 <= RECENT)


def test_a_window_never_read_copies_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    copies: list[int] = []
    flush = Columns._flush

    def counted(self: Columns) -> None:
        copies.append(len(self))
        flush(self)

    monkeypatch.setattr(livewindow.Columns, "_flush", counted)
    size = livewindow.HALF_WINDOW
    window = Columns(NAMES, size)
    for k in range(3 * size + 5):
        window.append(*_row(k))
    assert copies == []  # appended, never read: no copy
    assert window.col("seq").tolist() == [float(k) for k in range(2 * size + 5, 3 * size + 5)]
    assert len(copies) == 1  # the read copies once
    window.col("t_s")
    window.col("counter")
    assert len(copies) == 1  # nothing appended since: no copy
    window.append(*_row(3 * size + 5))
    assert window.col("seq")[-1] == 3 * size + 5
    assert len(copies) == 2
