"""A step within a period of the ambiguity threshold: the judges follow the firmware's own word
(issue #11, rule 3: a FAIL must never blame a correct firmware; ``host.judge.ambiguity``).

The firmware decides whether a step is too long to read on its own clock (the COUNTER advance
plus the whole 16-period cycles nearest the ticks since the last accepted frame:
``step_periods.widened_periods``' rule); the judges count those ticks on bus time. A log's
times jitter (a recorder's stamps, a loaded host), and after mailbox drops the firmware's count
is wider than the bus's: one period either way moves a silence near a half cycle onto the other
side of the threshold (kobuki: 392 periods of silence are integrated, 393 re-primed). Where the
decision at the bus time's periods and at one period more or less differ (``near``), the judges
cannot know which the firmware took, and take its own word: ERROR_MASK's sticky COUNTER_RESET
in its ODOM_STATUS summaries, clear on the last summary sent before the frame after the step and
set on the first sent two periods after it, says it re-primed there; clear on both, that it did
not. Where its word is not heard (no summary around, or COUNTER_RESET latched before), the
judge's own decision stands. Far from the threshold nothing changes: a firmware that integrated
a guess across a silence well past it still FAILs.

The streamed judge steps before it reads the summaries: it refuses a life where the firmware's
word at a long gap differs from its re-primes (``disagrees``), and the whole log's judge judges
it. The live judge steps before the firmware's word comes: at such a step it restarts its
reference from the next on-board pose (``livedark.DarkRestarts.owe``, the ``NEAR_DETAIL``
event), as after a dark restart: either decision passes, the one pose jump there is not judged.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.ambiguity import least_ambiguous_periods
from odocan.host.judge.reference import Geometry, SpeedBound
from odocan.host.judge.samples import FloatArray, IntArray
from odocan.host.judge.step_periods import pair_bound_periods, widened_periods
from odocan.host.protocol import busfacts
from odocan.host.protocol.decode import BulkDecoder, DecodeError

if TYPE_CHECKING:
    from odocan.host.judge.samples import Encoders

NEAR_DETAIL = ("a silence within a period of the ambiguity threshold: the firmware may have "
               "re-primed or integrated it (its clock, not the bus's, decides); the live "
               "reference restarts from the next on-board pose")
COUNTER_RESET_BIT = 1 << 9  # ERROR_MASK bit 9 (firmware.errors.ErrorFlag.COUNTER_RESET)
SUMMARY_PAGE = busfacts.SUMMARY_PAGE  # ODOM_STATUS page with STATE, REASON, ERROR_MASK
AFTER_PERIODS = 2  # the first summary this many periods after the frame: made after it


def near(seq_periods: int, elapsed_s: float, cycle_s: float | None, least: int) -> bool:
    """Whether the step's ambiguity (its widened periods reaching ``least``) differs at one
    period more or less of bus time than ``elapsed_s``."""
    if cycle_s is None:
        return False
    elapsed = np.array([elapsed_s - cycle_s, elapsed_s, elapsed_s + cycle_s])
    periods = widened_periods(np.full(3, seq_periods, dtype=np.int64), elapsed, cycle_s)
    return len({bool(p >= least) for p in periods.tolist()}) > 1


@dataclass(frozen=True)
class Resets:
    """The firmware's summaries (bus time, ERROR_MASK) and the log's long gaps (frame after:
    the bus times of the frames either side, the sequence step), for ``told`` and
    ``disagrees``."""

    sent_s: FloatArray = field(default_factory=lambda: np.zeros(0))
    mask: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    long_gaps: dict[int, tuple[float, float, int]] = field(default_factory=dict)
    cycle_s: float = busfacts.ENC_CYCLE_S  # the WHEEL_ENCODERS cycle
    holes: frozenset[int] = frozenset()  # ``gapseen.Seen.holes``: no word of the log's step

    def told(self, b_s: float) -> bool | None:
        """Whether the firmware re-primed on the encoder frame at bus time ``b_s`` by its own
        COUNTER_RESET (module docstring); None when it does not say."""
        i = int(np.searchsorted(self.sent_s, b_s, side="left")) - 1
        j = int(np.searchsorted(self.sent_s, b_s + AFTER_PERIODS * self.cycle_s, side="right"))
        if i < 0 or j >= len(self.sent_s) or self.mask[i] & COUNTER_RESET_BIT:
            return None
        return bool(self.mask[j] & COUNTER_RESET_BIT)

    def disagrees(self, reprimed: frozenset[int], least: int | None,
                  holes: frozenset[int] = frozenset()) -> bool:
        """Whether the firmware's word at a long gap within a period of the threshold
        (``least``: the fewest periods of an ambiguous step) differs from re-priming there."""
        return least is not None and any(
            near(step, b_s - a_s, self.cycle_s, least) and (word := self.told(b_s)) is not None
            and word != (frame in reprimed) and frame not in holes
            for frame, (a_s, b_s, step) in self.long_gaps.items())


@dataclass
class ResetLog:
    """The summaries' ERROR_MASK fed chunk by chunk (``gapseen.PageEvidence``)."""

    sent_s: list[FloatArray] = field(default_factory=list)
    mask: list[IntArray] = field(default_factory=list)
    usable: bool = True

    def feed(self, chunk: FrameArrays, decoder: BulkDecoder, accepted: IntArray | None = None
             ) -> None:
        """The chunk's summaries (whose CRC holds: ``accepted``, rows of the chunk)."""
        if not self.usable:
            return
        try:
            page = decoder.decode_page(chunk, "ODOM_STATUS", SUMMARY_PAGE)
        except (DecodeError, KeyError):
            self.usable = False
            return
        if "ERROR_MASK" not in page:
            self.usable = False
            return
        keep = (np.ones(len(page["index"]), dtype=bool) if accepted is None
                else np.isin(page["index"], accepted))
        self.sent_s.append(np.asarray(page["timestamp_s"], dtype=np.float64)[keep])
        self.mask.append(np.asarray(page["ERROR_MASK"], dtype=np.int64)[keep])

    def resets(self, long_gaps: dict[int, tuple[float, float, int]], cycle_s: float | None,
               holes: frozenset[int] = frozenset()) -> Resets:
        """What was fed, with the log's long gaps and holes."""
        if not self.usable or not self.sent_s or cycle_s is None:
            return Resets(long_gaps=dict(long_gaps), holes=holes)
        return Resets(np.concatenate(self.sent_s), np.concatenate(self.mask), dict(long_gaps),
                      cycle_s, holes)


def ambiguity_rule(enc: Encoders, e0: int, least: int, through: dict[int, int],
                   resets: Resets | None, holes: frozenset[int] = frozenset()
                   ) -> Callable[[int, int], bool]:
    """``reference_path.firmware_steps``' test whether the step from frame ``a`` (the last
    accepted, from ``e0``) to frame ``b`` is ambiguous: its periods reach ``least``, unless the
    pages prove frames taken in the gap (``through``: ``holetaken``); within a period of the
    threshold the firmware's own word (``resets``, module docstring) where it says one, but
    not behind a hole of the log (``holes``: the firmware may have taken frames the log lacks,
    one by one; its word then says nothing of the log's step)."""
    seq, stamps = enc.seq[e0:], enc.timestamp_s[e0:]

    def ambiguous(a: int, b: int) -> bool:
        if b == a + 1 and through.get(e0 + b, least) < least:
            return False
        decided = pair_bound_periods(seq, stamps, enc.cycle_s, a, b) >= least
        elapsed_s = float(stamps[b] - stamps[a])
        if resets is None or e0 + b in holes or not near(int(seq[b] - seq[a]), elapsed_s,
                                                         enc.cycle_s, least):
            return decided
        word = resets.told(float(stamps[b]))
        return decided if word is None else word

    return ambiguous


def near_candidates(seq: IntArray, stamps: FloatArray, cycle_s: float | None, least: int,
                    resets: Resets | None) -> npt.NDArray[np.bool_]:
    """Per step (into frame k + 1): whether one period more of bus time makes it ambiguous
    (so ``ambiguity_rule`` decides it; none without ``resets``)."""
    if resets is None or cycle_s is None or len(seq) < 2:
        return np.zeros(max(len(seq) - 1, 0), dtype=np.bool_)
    longer: npt.NDArray[np.bool_] = widened_periods(np.diff(seq), np.diff(stamps) + cycle_s,
                                                    cycle_s) >= least
    return longer


def least_of(geometry: Geometry, bits: int, max_wheel_speed_mm_s: SpeedBound) -> int | None:
    """The fewest periods of an ambiguous step (``ambiguity.least_ambiguous_periods``) from the
    speed bound as ``reference_path.firmware_steps`` takes it; None without one."""
    speed_mm_s = geometry.speed_bound_mm_s(max_wheel_speed_mm_s)
    if speed_mm_s is None:
        return None
    return least_ambiguous_periods(geometry.period_counts(speed_mm_s), bits)
