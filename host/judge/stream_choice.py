"""Whether ``odocan analyze`` streams a log (``host.judge.stream_analysis``) or reads it whole:
a choice made from the log's size alone, before anything is read, without importing the
streamed judge (a whole-log analysis never needs it)."""

from __future__ import annotations

from pathlib import Path

STREAM_MODES = ("auto", "always", "never")
RSS_TARGET_MB = 300.0  # the max RSS ``odocan analyze`` of one log aims to stay under (#14.1)
# The whole-log path's max RSS (MB) against its log's size (MB), per format: base + per_mb * size,
# measured by ``bench/analyze_memory.py --threshold`` (docs/benchmarks.md); a log bigger than
# the size where that reaches RSS_TARGET_MB / RSS_MARGIN streams.
WHOLE_RSS_MB = {".log": (65.4, 2.738), ".asc": (54.6, 1.888), ".blf": (52.2, 21.480)}
RSS_MARGIN = 1.2  # over a worst-case fit (one long life): 250 MB, the bench log stays whole
# A log the stream refused (``NotStreamable``) is read whole, after the stream's attempt: an
# hour's .log (52.7 MB) took 277-302 MB (pmir on the circle, a stall: ``bench/stream_stall.py``)
# and 329 MB (kobuki, a config applied: ``--config``; the whole path alone 326 MB, 6.2 MB per MB
# of log where WHOLE_RSS_MB's fit, of another drive, says 210): the refusal line takes the fit's
# base and 1.83x its slope (5.0 MB per MB of .log), above every one measured (121, 165 MB at
# 12.9, 26.1 MB; docs/benchmarks.md).
REFUSED_SLOPE_OVER_WHOLE = 1.83


def stream_above_bytes(suffix: str) -> float:
    """The log size (bytes) above which ``odocan analyze`` streams a log of this format (a
    format not measured: the most memory-hungry one's)."""
    base, per_mb = WHOLE_RSS_MB.get(suffix.lower(), max(WHOLE_RSS_MB.values(),
                                                        key=lambda fit: fit[1]))
    return max(0.0, (RSS_TARGET_MB / RSS_MARGIN - base) / per_mb) * 1e6


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
    whole-log path would take more than the max-RSS target for a log that size (the streamed
    path costs about 3x its CPU; the report is the same either way)."""
    if mode != "auto":
        return mode == "always"
    try:
        size = Path(path).stat().st_size
    except OSError:
        return False  # the whole-log path names the path in its error
    return size > stream_above_bytes(Path(path).suffix)
