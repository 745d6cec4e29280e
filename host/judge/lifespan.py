"""One firmware life of a log streamed chunk by chunk (``host.judge.stream_lives``; split from
it: its size)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class LifeSpan:
    """One firmware life: frames ``[start, stop)`` of the log (``host.judge.reboots.Life``)."""

    start: int
    stop: int
    boot: bool
    t_s: float | None = None
    uptime_before_s: int | None = None
    set_pose: Any = None  # a set-pose's piece (``setposes.SetPoseCut``: ``stream_cuts``)
    config: Any = None  # an applied config's piece (``configs.ConfigCut``)
    silent: bool = False  # primed in a silence on a frame nothing names (``silentboot``)
