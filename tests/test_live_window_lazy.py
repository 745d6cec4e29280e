"""The live judge's window (``livewindow.Columns``) copies its rows into numpy only when a column
is read: a window never read (a pose half window, mostly) copies nothing however long it runs,
and a read copies once, the rows appended since the one before. Whatever the reads, a column is
the latest ``size`` rows appended, float64, as an independent float64 array of every row
appended gives them; ``rows`` the latest ``RECENT`` tuples, ``whole`` and ``len`` as before.
The loss judge's page (``livelosses.LiveAllowance.on_page``) tells a quiet page (no loss, no
sender step of 0 since the page before) from the rows as tuples (``Columns.latest_from``, the
rows ``searchsorted`` cuts), copying none, and judges every page as it does from the
columns."""

from __future__ import annotations

import random

import numpy as np
import pytest

from odocan.host.judge import livelosses, livewindow
from odocan.host.judge.livelosses import LiveAllowance
from odocan.host.judge.livewindow import ENC_COLUMNS, ENC_WINDOW, RECENT, Columns
from odocan.host.judge.reference import Geometry
from odocan.sim.robot import load

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


@pytest.fixture
def copies(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """The rows each copy into numpy held (``Columns._flush`` counted), in order."""
    counts: list[int] = []
    flush = Columns._flush

    def counted(self: Columns) -> None:
        counts.append(len(self))
        flush(self)

    monkeypatch.setattr(livewindow.Columns, "_flush", counted)
    return counts


def test_a_window_never_read_copies_nothing(copies: list[int]) -> None:
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


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_latest_from_gives_the_rows_searchsorted_cuts(seed: int) -> None:
    rng = random.Random(seed)
    size = 64
    window, told = Columns(NAMES, size), 0
    for k in range(10 * size):
        window.append(*_row(k))
        if rng.random() < 0.05:
            window.col("seq")  # some rows copied
        first = k - rng.randrange(0, size + 8)
        rows = window.latest_from(first)
        if rows is None:
            continue  # more than RECENT copied rows back: ``col`` reads them
        told += 1
        copied = Columns(NAMES, size)  # the same rows, read through ``col``
        for j in range(max(0, k + 1 - size), k + 1):
            copied.append(*_row(j))
        i0 = int(np.searchsorted(copied.col("seq"), first))
        expected = [tuple(copied.col(n)[i].item() for n in NAMES)
                    for i in range(i0, len(copied))]
        assert rows == expected, (k, first)
    assert told > 5 * size


def _paged(window: Columns, pages: list[tuple[int, int]]) -> list[tuple[int, float]]:
    allowance = LiveAllowance()
    geometry = Geometry.of(load("pmir"))
    for lost, upto in pages:
        allowance.on_page(lost, upto, window, set(), (geometry, 16, "exact"))
    return allowance.spans


def _drive(seed: int) -> tuple[Columns, list[tuple[int, int]]]:
    """An encoder window with sender steps of 0 here and there, and its pages (ENC_E2E_LOST
    growing now and then)."""
    rng = random.Random(seed)
    window, pages, counter, lost = Columns(ENC_COLUMNS, ENC_WINDOW), [], 0, 0
    for seq in range(1500):
        counter = (counter + (0 if rng.random() < 0.01 else 1)) & 0xF
        window.append(seq, seq, counter, 0.01 * seq, 3 * seq, 3 * seq, 1, 0)
        if seq % 60 == 59:
            lost += 2 if rng.random() < 0.2 else 0
            pages.append((lost & 0xFF, seq))
    return window, pages


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_a_page_told_from_plain_rows_as_from_the_columns(seed: int,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    plain = _paged(*_drive(seed))
    monkeypatch.setattr(livelosses, "_quiet", lambda _window, _first: False)
    assert plain == _paged(*_drive(seed))


def test_a_quiet_page_copies_no_row(copies: list[int]) -> None:
    window = Columns(ENC_COLUMNS, ENC_WINDOW)
    pages = []
    for seq in range(1000):
        window.append(seq, seq, seq & 0xF, 0.01 * seq, 3 * seq, 3 * seq, 1, 0)
        if seq % 60 == 59:
            pages.append((0, seq))
    assert _paged(window, pages) == []
    assert copies == []
