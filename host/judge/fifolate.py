"""A late encoder frame a resumed firmware took from its receive FIFO before it re-primed (issue
#11, rule 5: a FAIL must never blame a correct firmware; ``host.judge.stallreprime``).

A halted MCU's CAN controller keeps the first ``HW_RX_FIFO_FRAMES`` frames after the halt
(``sim.board``). Under a delaying bus one of them can be a late WHEEL_ENCODERS frame, sent
before the last frame the firmware took: the host's E2E, which never stalled, refuses it
(reordered), but the resumed firmware's E2E window is wide open after the stall and its
plausibility bound about twice the stall, so it takes the late frame as one step back in time,
then re-primes on the next fresh one. Its heading after the re-prime is then the late frame's
(heading is linear in the counts), not any accepted frame's: on kobuki halted 2 s
(``--scenario random --seed 2 --faults delay=0.3:55,dup=0.1,stall=4:2``) the firmware took seq
399 (3.99 s), then the late seq 394 stamped 3.995 s, then re-primed on seq 601; no pair of
accepted frames fits, and the nearest (f seq 398, r seq 603) left the correct firmware 2.0 mm,
13.4 mrad off.

So the re-prime's candidates for ``f`` also hold each refused CRC-right frame of the log
(``refusedenc``) stamped after an accepted frame ``k`` of f's range: the firmware's path is the
reference's up to ``k``, then that one step (``LateStep``: its counts less ``k``'s, integrated
as the firmware integrates a step), then nothing until it re-primes. The step is put in the
reference as the step into ``k + 1`` (``stallreprime.left_out``). What a wrong firmware can
hide by it: no more than by the accepted frames' pairs (a heading of frames around the stall
it declared); a wrong position or any wrong step after still FAILs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from odocan.host.judge.reference import Geometry, integrate, wrap_delta
from odocan.host.judge.refusedenc import Refused as Refused

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class LateStep:
    """A late frame the firmware may have taken after accepted frame ``k`` (from e0): its
    counts less ``k``'s, and that step's arc in ``k``'s frame (x, y m, turn rad)."""

    k: int
    d_left: int
    d_right: int
    x_m: float
    y_m: float
    turn_rad: float


@dataclass(frozen=True)
class Judged:
    """What a late step is integrated with: the robot's geometry, integrator, counter bits."""

    geometry: Geometry
    integrator: str
    bits: int


def late_step(k: int, counts: tuple[int, int], base: tuple[int, int], judged: Judged) -> LateStep:
    """The ``LateStep`` into a late frame's ``counts`` from accepted frame ``k``'s ``base``."""
    d_left = int(wrap_delta(counts[0] - base[0], judged.bits))
    d_right = int(wrap_delta(counts[1] - base[1], judged.bits))
    arc = integrate([d_left], [d_right], judged.geometry, judged.integrator)
    return LateStep(k, d_left, d_right, float(arc.x_m[0]), float(arc.y_m[0]),
                    float(arc.heading_rad[0]))


def after_frames(refused: Refused | None, enc_t_s: FloatArray) -> IntArray:
    """Per refused frame, the last accepted frame stamped at or before it (-1: none)."""
    if refused is None:
        return np.zeros(0, dtype=np.int64)
    return np.searchsorted(enc_t_s, refused.t_s, side="right").astype(np.int64) - 1


def late_steps(refused: Refused | None, after: IntArray, span: tuple[int, int],
               enc_counts: tuple[IntArray, IntArray], e0: int, judged: Judged) -> list[LateStep]:
    """The ``LateStep`` of every refused frame after an accepted frame in ``span`` (first,
    last, from e0; ``after``: ``after_frames``; ``enc_counts``: the accepted frames' counts)."""
    if refused is None or len(after) == 0:
        return []
    lo, hi = span
    out = []
    for j in np.flatnonzero((after >= lo + e0) & (after <= hi + e0)).tolist():
        k = int(after[j])
        out.append(late_step(k - e0, (int(refused.left[j]), int(refused.right[j])),
                             (int(enc_counts[0][k]), int(enc_counts[1][k])), judged))
    return out
