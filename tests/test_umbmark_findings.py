"""``umbmark.Refusal`` and ``umbmark.Calibration`` share what a calibration found (issue #11's
last note): the fields are declared once, in ``umbmark.Findings``, and both still take them
positionally in the same order as before."""

from __future__ import annotations

import dataclasses
from typing import Any

from odocan.host.experiments import umbmark

SHARED = ("before", "borenstein", "model", "method", "nominal", "corrected")


def test_the_findings_are_declared_once_and_shared() -> None:
    assert [f.name for f in dataclasses.fields(umbmark.Findings)] == list(SHARED)
    for cls in (umbmark.Calibration, umbmark.Refusal):
        assert issubclass(cls, umbmark.Findings)
        assert not set(SHARED) & set(vars(cls).get("__annotations__", {}))  # not restated
        assert tuple(f.name for f in dataclasses.fields(cls))[:len(SHARED)] == SHARED


def test_positional_construction_is_unchanged() -> None:
    values = [object() for _ in SHARED]
    calibration: Any = umbmark.Calibration  # placeholders for the values: only their places count
    refused: Any = umbmark.Refusal
    cal = calibration(*values, "after", 0.25)
    refusal = refused(*values, 0.5, (1.01, 0.99))
    assert [getattr(cal, name) for name in SHARED] == values
    assert (cal.after, cal.fit_residual_m) == ("after", 0.25)
    assert calibration(*values, "after").fit_residual_m == 0.0
    assert [getattr(refusal, name) for name in SHARED] == values
    assert (refusal.fit_residual_m, refusal.estimated) == (0.5, (1.01, 0.99))
