"""Silences the E2E COUNTER cannot count: a message heard again after 16 periods or more.

Profile 2's COUNTER is 4 bits: after 16 periods without a frame it has gone round, so the
``lost`` count it gives (``delta - 1``, mod 16) is a lower bound only: a 20 s bus-off of the
10 ms WHEEL_ENCODERS read "lost 1" for 2000 frames missing. The receiver says it apart:
``silences`` the steps between two accepted frames of a message ``SILENCE_PERIODS`` receive
periods or more apart (15.5: from 15 frames missing the COUNTER steps by 0 mod 16, round half
up), and ``silence_ms`` their total length (ms, int: each silence rounded to the ms on its
own, then added, so that a log read whole, a log read chunk by chunk as ``host.judge.stream``
adds the counts, and the live receiver counting one silence at a time say the same number).
Both keys are present only when a silence was heard, in ``check_frames``' counts, the live
receiver's (the monitor, the bridge's ``rates``) and the reports; ``lost_text`` says the count
the way every view prints it.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import numpy.typing as npt

from odocan.host.protocol.e2e_cycles import COUNTER_CYCLE

SILENCE_PERIODS = COUNTER_CYCLE - 0.5  # a step this many receive periods long: uncountable
SILENCE_KEYS = ("silences", "silence_ms")


def is_silence(step_s: float, period_s: float | None) -> bool:
    """Whether two accepted frames ``step_s`` apart are too far for the COUNTER to count the
    frames between (``period_s``: the message's receive period; None: not cyclic, never)."""
    return period_s is not None and step_s >= SILENCE_PERIODS * period_s


def silences(t_s: npt.NDArray[np.float64], period_s: float | None) -> dict[str, int]:
    """The silences between consecutive accepted frames at bus times ``t_s`` (module
    docstring): ``{}`` when none."""
    if period_s is None or len(t_s) < 2:
        return {}
    step_s = np.diff(t_s)
    long_s = step_s[step_s >= SILENCE_PERIODS * period_s]
    if len(long_s) == 0:
        return {}
    return {"silences": len(long_s), "silence_ms": sum(silence_ms(float(s)) for s in long_s)}


def silence_ms(step_s: float) -> int:
    """One silence's length in whole ms: the unit every count of them adds."""
    return round(step_s * 1e3)


def add_silence(counts: dict[str, int], step_s: float) -> None:
    """Count one silence of ``step_s`` seconds into ``counts`` (the live receiver)."""
    counts["silences"] = counts.get("silences", 0) + 1
    counts["silence_ms"] = counts.get("silence_ms", 0) + silence_ms(step_s)


def lost_text(counts: Mapping[str, object], *, cell: bool = False) -> str:
    """The ``lost`` count as every view prints it: ``"3"``, or ``"≥ 1 (silence 20.0 s)"``
    when a silence made the COUNTER's count a lower bound; ``cell``: ``"≥ 1"`` for a table
    whose caption says why (``silence_caption``); "-" without a count."""
    lost = counts.get("lost")
    if not isinstance(lost, int):
        return "-"
    heard, length_ms = counts.get("silences"), counts.get("silence_ms")
    if not isinstance(heard, int) or not heard or not isinstance(length_ms, int):
        return str(lost)
    if cell:
        return f"≥ {lost}"
    what = "silence" if heard == 1 else f"{heard} silences"
    return f"≥ {lost} ({what} {length_ms / 1e3:.1f} s)"


def silence_caption(e2e: Mapping[str, Mapping[str, object]]) -> str | None:
    """Below a table of ``lost`` cells: why some read "≥" (the longest total silence and the
    messages it hid frames of), else None."""
    silent = {name: c.get("silence_ms") for name, c in e2e.items() if c.get("silences")}
    lengths_ms = [v for v in silent.values() if isinstance(v, int)]
    if not lengths_ms:
        return None
    names = "every message" if len(silent) == len(e2e) else ", ".join(silent)
    return (f"lost ≥: silent up to {max(lengths_ms) / 1e3:.1f} s ({names}), longer than a "
            f"COUNTER cycle ({COUNTER_CYCLE} periods): the frames lost then are not counted")
