"""The verdict of ``analyze`` with ``host.judge.namesahead``'s rule: a pose frame naming an
encoder frame not yet sent FAILs the log (``checked``), and where nothing pairs (every pose so
named) the error says that defect, exit 1 (``NamesAheadError``), not "nothing to compare"."""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, ParamSpec, Protocol, TypeVar, cast

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.namesahead import AheadScan, mark, report_of
from odocan.host.judge.samples import AnalysisError, require_messages
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import check_frames

if TYPE_CHECKING:  # a cantools Database or a plan of it (host.protocol.dbcplan)
    from odocan.host.protocol.dbcplan import DatabaseSpec


class _Verdict(Protocol):
    report: dict[str, Any]
    passed: bool


class NamesAheadError(AnalysisError):
    """Nothing to compare, and pose frames name encoder frames not yet sent: the firmware's
    defect is the verdict (a FAIL, exit 1), not bad input."""

    exit_code = 1


P = ParamSpec("P")
R = TypeVar("R", bound=_Verdict)


def checked(analyze: Callable[P, R]) -> Callable[P, R]:
    """``analyze`` (its first argument the frames, ``db`` a keyword) whose verdict is a FAIL
    when a pose frame names an encoder frame not yet sent (``mark``), and whose "nothing to
    compare" names that defect (``NamesAheadError``)."""

    @functools.wraps(analyze)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        frames = args[0]
        assert isinstance(frames, FrameArrays)
        db = cast("DatabaseSpec", kwargs.get("db") or default_plan())
        decoder = BulkDecoder(db)
        require_messages(decoder)  # analyze's own words for a DBC without them, said first
        scan = AheadScan(decoder)
        scan.feed(frames, check_frames(frames, db)[1])
        try:
            result = analyze(*args, **kwargs)
        except AnalysisError as exc:
            raise failed(scan, exc) from exc
        mark(result.report, scan)
        result.passed = result.passed and bool(result.report["passed"])
        return result

    return wrapper


def failed(scan: AheadScan, exc: AnalysisError) -> AnalysisError:
    """``exc``, or a ``NamesAheadError`` saying the defect ``scan`` found."""
    if not scan.count:
        return exc
    return NamesAheadError(f"{report_of(scan.found, scan.count)['detail']} ({exc})")
