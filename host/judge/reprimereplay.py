"""Where a declared re-prime after a long stall puts the firmware, replayed from the frames it
took (issue #11, rule 5: a PASS must never hide a wrong pose; the live half of
``stallreprime._chosen``, for ``livereprime``).

A firmware that re-primes after a long stall (COUNTER_RESET) has, at its first pose after it,
its pose before the stall (the anchor: its last sample compared, or the power-up pose on the
frame its life primed on) stepped over the frames its receive FIFO kept (the anchor's frame
to ``f``, at most ``FIFO_SPAN`` and one more later), then re-primed on a frame ``r`` (at most
``R_SPAN`` before the first sample kept) and stepped from there: the stall's motion and its
turn left out. Every one of those frames is on the bus. The live judge keeps the latest
encoder frames when the firmware fell silent (``QuietFrames``: its window of recent rows as
they were ``FROZEN_AFTER`` frames after its last pose half or ODOM_STATUS; a stall longer than
the window, 5 s, has long dropped them from it by the time its word comes) and the window
holds the frames from ``r`` on. ``replayed`` walks every pair (f, r) from the anchor in
float64 (the tracker's integrator) and takes the one whose path best meets the samples held
(position and heading, in LSBs, the worst sample: ``_chosen``'s score); the firmware's first
poses must lie within ``TIGHT_POSITION_M`` and ``TIGHT_HEADING_RAD`` of it (``Replayed.within``:
the anchor's rounding and the samples', half an LSB each per axis, and the firmware's own
drift, far below). Before, only a bound from the speed bound (about 0.26 m on pmir) held it,
and a firmware 10 mm off from its first pose after the re-prime PASSed live while ``analyze``
FAILed it. None when the frames it needs are not held (the caller falls back and says so): a
frame of the FIFO's span not kept, a hole of the log among them or before a life's primed frame
(the firmware may have taken a frame the log lacks), or before the first sample kept; a hole
after it only leaves the samples beyond it to be judged as they come.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

from odocan.host.judge.livepose import FramePose
from odocan.host.judge.livewindow import Counted
from odocan.host.judge.reference import Geometry, ReferenceOdometry
from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M
from odocan.host.judge.stallreprime import COMPARED, FIFO_SPAN, R_SPAN

FROZEN_AFTER = 12  # encoder frames of the firmware's silence the rows kept reach past it
TIGHT_POSITION_M = 2 * POSITION_LSB_M  # two poses' rounding (anchor, sample), both axes
TIGHT_HEADING_RAD = 2 * HEADING_LSB_RAD
_TURN = 2.0 * math.pi

# left, right raw counts and the sender's periods since the frame heard before, by seq
Counts = dict[int, tuple[int, int, int]]


class QuietFrames:
    """The window's latest rows as they were ``FROZEN_AFTER`` encoder frames after the
    firmware's last pose half or ODOM_STATUS (``since``: frames heard since it; the tracker
    zeroes it when the firmware talks and calls ``heard`` per encoder frame)."""

    __slots__ = ("frozen", "since")

    def __init__(self) -> None:
        self.since = 0
        self.frozen: tuple[tuple[float, ...], ...] = ()  # ``livewindow.ENC_COLUMNS`` rows

    def heard(self, rows: Iterable[tuple[float, ...]]) -> None:
        """An encoder frame appended to the window whose latest rows are ``rows``."""
        self.since += 1
        if self.since == FROZEN_AFTER:
            self.frozen = tuple(rows)


@dataclass(frozen=True)
class Replayed:
    """The re-primed path that best meets the samples: its pose at the first sample's frame,
    the frames chosen (f, r) and the worst sample's position (m) and heading (rad) offsets."""

    pose: FramePose
    f: int
    r: int
    position_m: float
    heading_rad: float

    @property
    def within(self) -> bool:
        """The samples are the re-prime's (module docstring)."""
        return self.position_m <= TIGHT_POSITION_M and self.heading_rad <= TIGHT_HEADING_RAD

    def said(self) -> str:
        """The words for a first pose beyond the bound."""
        return (f"its first pose after it {self.position_m * 1e3:.2f} mm and "
                f"{self.heading_rad * 1e3:.2f} mrad from where the frames it took put it "
                f"(stepped to frame {self.f}, re-primed on {self.r}): no re-prime's")


@dataclass(frozen=True)
class Odometry:
    """What the walks integrate with: the tracker's geometry, integrator and counter bits."""

    geometry: Geometry
    integrator: str
    bits: int

    def walk(self, start: FramePose, counts: Counts, seqs: range) -> dict[int, FramePose]:
        """The poses from ``start`` primed on the first of ``seqs`` and stepped over the rest
        (float64); it stops at a frame not in ``counts`` or after a hole of the sender's
        sequence (a frame the log lacks: which frames the firmware took there is unknown)."""
        odo = ReferenceOdometry(self.geometry, self.integrator, self.bits, x_m=start.x_m,
                                y_m=start.y_m, heading_rad=start.heading_rad)
        out: dict[int, FramePose] = {}
        for seq in seqs:
            left, right, periods = counts.get(seq, (0, 0, 0))
            if seq not in counts or (out and periods != 1):
                break
            odo.step_counts(left, right)
            out[seq] = FramePose(seq, odo.x_m, odo.y_m, odo.heading_rad)
        return out


def replayed(odometry: Odometry, anchor: FramePose, frozen: Iterable[tuple[float, ...]],
             recent: list[Counted], samples: list[FramePose], primed: bool = False
             ) -> Replayed | None:
    """The best pair's path (module docstring) from ``anchor`` (the firmware's pose on its
    frame; ``primed``: a life's power-up pose on the frame it primed on, which must not follow
    a hole of the log, where it may have primed on a frame the log lacks) over the ``frozen``
    rows (``QuietFrames``) and the ``recent`` frames (the window's from the earliest ``r``
    on), met with the first ``COMPARED`` ``samples`` held; None when the frames it needs are
    not held."""
    paths = replays(odometry, anchor, frozen, recent, samples, primed)
    return None if not paths else min(paths, key=score)


def score(replay: Replayed) -> float:
    """How far a replay's path lies from the samples: the worst sample's position and heading
    offsets in LSBs (``stallreprime._chosen``'s score)."""
    return replay.position_m / POSITION_LSB_M + replay.heading_rad / HEADING_LSB_RAD


def replays(odometry: Odometry, anchor: FramePose, frozen: Iterable[tuple[float, ...]],
            recent: list[Counted], samples: list[FramePose], primed: bool = False
            ) -> list[Replayed] | None:
    """Every pair's path (``replayed``'s arguments): ``replayed`` takes the best, the count
    page's rule (``livereprimecount``) the ones its ENC_E2E_LOST allows; None when the frames
    it needs are not held."""
    samples = samples[:COMPARED]
    first, last = samples[0].seq, samples[-1].seq
    kept: Counts = {int(row[0]): (int(row[4]), int(row[5]), int(row[6])) for row in frozen}
    f_hi = min(anchor.seq + FIFO_SPAN + 1, first - 1)
    if primed and anchor.seq > 0 and kept.get(anchor.seq, (0, 0, 0))[2] != 1:
        return None
    before = odometry.walk(anchor, kept, range(anchor.seq, f_hi + 1))
    r_lo = first - R_SPAN
    after: Counts = {c[0]: (c[2], c[3], c[4]) for c in recent}
    heard = odometry.walk(anchor, after, range(r_lo, last + 1))  # up to a hole of the log
    if f_hi not in before or first not in heard:  # a frame it may have taken not held
        return None
    samples = [s for s in samples if s.seq in heard]  # the later ones: judged as they come
    last = samples[-1].seq
    out: list[Replayed] = []
    for f, at_f in before.items():
        for r in range(max(f + 1, r_lo), first + 1):
            path = odometry.walk(at_f, after, range(r, last + 1))
            worst = _worst(path, samples)
            if worst is not None:
                out.append(Replayed(path[first], f, r, *worst))
    return out


def _worst(path: dict[int, FramePose], samples: list[FramePose]) -> tuple[float, float] | None:
    """The largest position (m) and heading (rad) offsets of ``samples`` from ``path``."""
    position_m = heading_rad = 0.0
    for sample in samples:
        at = path.get(sample.seq)
        if at is None:
            return None
        position_m = max(position_m, math.hypot(sample.x_m - at.x_m, sample.y_m - at.y_m))
        heading_rad = max(heading_rad, abs(math.remainder(sample.heading_rad - at.heading_rad,
                                                          _TURN)))
    return position_m, heading_rad
