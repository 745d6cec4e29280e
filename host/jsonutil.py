"""JSON of reports, snapshots and MQTT payloads: JSON has no NaN, so non-finite floats are null.

One writer for every ``--report``: strict JSON (numpy scalars and arrays as numbers and lists,
NaN and infinities as null), an I/O error naming the path.

It lives at host/ level, below every room, so io/ and judge/ write JSON without importing
report/.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np


def finite(value: Any) -> Any:
    """``value`` with every non-finite float (numpy's too) replaced by None, keys as strings."""
    if isinstance(value, dict):
        return {str(key): finite(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [finite(item) for item in value]
    if isinstance(value, float | np.floating) and not math.isfinite(value):
        return None
    return value


def real(value: Any) -> float | None:
    """``value`` as a finite float; None for anything else (None, text, a list, NaN, a bool, a
    JSON integer beyond every float): what MQTT hands the fleet view is not trusted."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    try:
        number = float(value)
    except OverflowError:
        return None
    return number if math.isfinite(number) else None


def json_default(value: object) -> object:
    """``json.dumps`` default: numpy scalars as Python numbers, arrays as lists."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serializable: {type(value).__name__}")


def report_json(report: dict[str, Any]) -> str:
    """``report`` as strict, indented JSON text (non-finite floats null), newline-terminated."""
    return json.dumps(finite(report), indent=2, default=json_default, allow_nan=False) + "\n"


def write_report(path: Path, report: dict[str, Any], option: str = "--report") -> None:
    """Write ``report_json(report)`` to ``path``; an I/O error is one ``OutputError`` naming
    ``option`` and the path."""
    from odocan.host.outputs import write_text

    write_text(path, report_json(report), option)
