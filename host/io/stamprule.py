"""The rule that tells a glitched stamp (``host.io.stampglitch``), one place for the log's
readers and the live judges' gate (``host.judge.livestampgate``): numpy-free, so the live gate
(compiled by ``host.accel``) takes it as the readers do.

A frame is glitched when its stamp is more than ``JUMP_S`` off both its neighbours in one
direction (ahead of both, or behind both) while its neighbours are in order (the next no more
than ``JUMP_S`` before the one before). ``lone`` says it of one frame (floats) or of every frame
of a log at once (numpy arrays: the operators work element-wise; nan, no neighbour there: no).
A frame within ``JUMP_S`` of the frame before it is never glitched (``off`` false): only the
frames ``off`` the one before need their next to be told.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, overload

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

JUMP_S = 1.0  # off both neighbours by more than this: 100 encoder periods, 6 COUNTER laps
MAX_SET_ASIDE = 16  # frames set aside at most: more is two clocks interleaved (stampglitch)


@overload
def lone(before_s: float, t_s: float, after_s: float) -> bool: ...


@overload
def lone(before_s: npt.NDArray[np.float64], t_s: npt.NDArray[np.float64],
         after_s: npt.NDArray[np.float64]) -> npt.NDArray[np.bool_]: ...


def lone(before_s: Any, t_s: Any, after_s: Any) -> Any:
    """A frame stamped ``t_s`` between frames stamped ``before_s`` and ``after_s`` (s) is a
    glitched stamp (module docstring); element-wise on arrays (numpy warns of nan: the caller's
    ``errstate``)."""
    ahead = (t_s - before_s > JUMP_S) & (t_s - after_s > JUMP_S)
    behind = (before_s - t_s > JUMP_S) & (after_s - t_s > JUMP_S)
    in_order = after_s >= before_s - JUMP_S  # (False where either is nan)
    return (ahead | behind) & in_order


def off(before_s: float, t_s: float) -> bool:
    """A frame stamped ``t_s`` is more than ``JUMP_S`` off the frame before it (``before_s``;
    nan: none): it may be glitched, its next tells."""
    return abs(t_s - before_s) > JUMP_S


def set_aside_text(count: int, number: int, t_s: float, prev_s: float, next_s: float) -> str:
    """What the readers' warning and the live judges' event say of ``count`` frames set aside,
    the first frame ``number`` (1-based among the frames heard) stamped ``t_s`` between
    ``prev_s`` and ``next_s`` (s)."""
    many = "s" if count > 1 else ""
    return (f"set aside {count} frame{many} stamped far off both neighbours (first: frame "
            f"{number}, {t_s:.6f} s, between {prev_s:.6f} and {next_s:.6f} s; more than "
            f"{JUMP_S:g} s off both while they are in order: a glitched stamp, no reorder nor "
            "pause): not judged, counted lost")
