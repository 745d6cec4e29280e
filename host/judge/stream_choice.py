"""Whether ``odocan analyze`` streams a log (``host.judge.stream_analysis``) or reads it whole:
a choice made from the log's size alone, before anything is read, without importing the
streamed judge (a whole-log analysis never needs it)."""

from __future__ import annotations

from pathlib import Path

STREAM_MODES = ("auto", "always", "never")
RSS_TARGET_MB = 300.0  # the max RSS ``odocan analyze`` of one log aims to stay under (#14.1)
RSS_MARGIN = 1.0  # the whole judge's budget RSS_TARGET_MB / RSS_MARGIN = 300 MB: no margin over
# the bound below, itself the worst drive measured (a margin streams more logs at 4-5x the CPU)
# The whole judge's max RSS (MB, GNU time's %M / 1024) against its log's size (MB), per format:
# base + per_mb * size, a bound over the shipped robots' hour-long drives (issue #13,
# docs/benchmarks.md). The worst is one long life with a config applied (kobuki,
# ``bench/stream_stall.py --config``): 111.8 / 172.4 / 233.9 / 307.2 MB at 13 / 26 / 39 /
# 52.7 MB of .log, under 48.0 + 4.92 MB per MB; an hour of pmir or kobuki on ``random``
# (55.3 MB) took 260-261 MB, pmir's hour with a 6 s stall (52.7 MB) 259 MB; a short log 46 MB.
# .asc: that hour through python-can (83.8 MB: 316.7 MB), the line from the small-log base
# (54.6 MB, ``bench/analyze_memory.py --threshold``). .blf: the old line's 21.5 MB per MB lies
# over the hour (14.0 MB: 316.6 MB); its base raised from 52.2 to 57.0 MB (a refused 70 kB .blf
# took 57 MB). Before (one short pmir drive's fit, 65.4 + 2.74 MB per MB of .log), ``auto``
# read a 52.7 MB hour whole at 307-326 MB. A log whose line passes the budget streams: above
# 51 MB of .log (about 56 minutes of the rig's drive), 78 MB of .asc, 11 MB of .blf.
WHOLE_RSS_MB = {".log": (48.0, 4.92), ".asc": (54.6, 3.13), ".blf": (57.0, 21.48)}
# A log the stream refused (``NotStreamable``) is read whole, after the stream's attempt: its
# max RSS was up to 1.15x the whole judge's line's slope above the base (refused, before this
# line: 121, 165, 277, 302, 329 MB at 12.9, 26.1, 52.7, 52.7, 52.7 MB of .log; 1.2x says 124,
# 202, 359 MB): the refusal line takes the line's base and 1.2x its slope.
REFUSED_SLOPE_OVER_WHOLE = 1.2


def stream_above_bytes(suffix: str) -> float:
    """The log size (bytes) above which ``odocan analyze`` streams a log of this format (a
    format not measured: the most memory-hungry one's)."""
    base, per_mb = WHOLE_RSS_MB.get(suffix.lower(), max(WHOLE_RSS_MB.values(),
                                                        key=lambda fit: fit[1]))
    return max(0.0, (RSS_TARGET_MB / RSS_MARGIN - base) / per_mb) * 1e6


def auto_budget() -> str:
    """What ``--stream auto`` chooses by, in words (``odocan analyze --help``): the whole
    judge's budget and the sizes above which each format streams."""
    sizes = ", ".join(f"{suffix} above {stream_above_bytes(suffix) / 1e6:.0f} MB"
                      for suffix in (".log", ".asc", ".blf"))
    return (f"{RSS_TARGET_MB / RSS_MARGIN:.0f} MB max RSS by the log's size ({sizes}: an "
            "hour of any shipped robot streams)")


def whole_rss_mb(path: str | Path) -> float | None:
    """About the max RSS (MB) the whole-log path takes on ``path`` (``WHOLE_RSS_MB``'s fit for
    its format, the most memory-hungry one's when not measured); None when it cannot be read."""
    return _fitted_rss_mb(path, 1.0)


def refused_rss_mb(path: str | Path) -> float | None:
    """About the most max RSS (MB) ``odocan analyze`` takes on ``path`` when the stream refused
    it (``WHOLE_RSS_MB``'s fit, its slope ``REFUSED_SLOPE_OVER_WHOLE`` times steeper); None when
    it cannot be read."""
    return _fitted_rss_mb(path, REFUSED_SLOPE_OVER_WHOLE)


def _fitted_rss_mb(path: str | Path, slope_factor: float) -> float | None:
    """``WHOLE_RSS_MB``'s fit for ``path``'s format, its slope times ``slope_factor``."""
    try:
        size_mb = Path(path).stat().st_size / 1e6
    except OSError:
        return None
    base, per_mb = WHOLE_RSS_MB.get(Path(path).suffix.lower(), max(WHOLE_RSS_MB.values(),
                                                                  key=lambda fit: fit[1]))
    return base + slope_factor * per_mb * size_mb


def streams(path: str | Path, mode: str = "auto") -> bool:
    """Whether to analyse ``path`` as a stream: ``always``, ``never``, or (``auto``) when the
    whole judge would take more than its budget (``RSS_TARGET_MB / RSS_MARGIN``, 300 MB) for a
    log that size by ``WHOLE_RSS_MB``'s bound (the streamed path costs 4-5x its CPU, and
    about 180 MB on an hour; the report is the same either way)."""
    if mode != "auto":
        return mode == "always"
    try:
        size = Path(path).stat().st_size
    except OSError:
        return False  # the whole-log path names the path in its error
    return size > stream_above_bytes(Path(path).suffix)
