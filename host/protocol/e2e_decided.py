"""Whether the stamps' reading decides an encoder frame's verdict, given the firmware's evidence
(issue #11, one judge; ``host.judge.liveearly``: a live hold ended once its first frame is).

``check_frames`` reads a pair of encoder frames three ways where a recorder may have stamped one
of them late (``e2e_evidence``: strict, wide, narrow) and lets the firmware's poses settle the
frames the readings judge differently. A frame is decided when every reading of its own stamp,
with the evidence heard so far, gives it the verdict the whole log's rule gives it: the poses
proved it taken or skipped, or proved a frame after it taken that no frame but the firmware's
last leads to (``e2e_retract``: a late frame the firmware took after it, which the bus held
back). A message whose readings all give one verdict to every frame decides each of them.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt

READINGS = (0, 1, 2)  # ``e2e_evidence.settle``'s: strict, wide, narrow
Run = Callable[[npt.NDArray[np.int8] | None], npt.NDArray[np.int8]]  # settle, a reading a frame


def all_decided(decided: dict[int, bool], index: npt.NDArray[np.intp]) -> None:
    """Every frame asked of the message at bus positions ``index``: decided (its readings agree
    on every frame)."""
    for pos in decided:
        j = int(np.searchsorted(index, pos))
        if j < len(index) and index[j] == pos:
            decided[pos] = True


def by_readings(decided: dict[int, bool], index: npt.NDArray[np.intp], run: Run,
                settled: npt.NDArray[np.int8]) -> None:
    """Each frame asked of the message (bus positions ``index``): decided when ``run`` with its
    own stamp read each way (the others as the rule reads them) gives it its ``settled``
    status every time."""
    for pos in decided:
        j = int(np.searchsorted(index, pos))
        if j >= len(index) or index[j] != pos:
            continue
        reading = np.full(len(index), -1, dtype=np.int8)
        codes = set()
        for way in READINGS:
            reading[j] = way
            codes.add(int(run(reading)[j]))
        decided[pos] = codes == {int(settled[j])}


def reading_key(reading: npt.NDArray[np.int8] | None, released: npt.NDArray[np.bool_]
                ) -> bytes | None:
    """A key of ``settle``'s per-frame ``reading`` (-1: the rule's), the same for readings it
    judges alike, so that ``_settled`` runs each once (``by_readings`` asks a frame's three
    ways; the rule's own way is ``run(None)``'s). After the first frame, the rule reads a frame
    by its pair's first frame's release, ``int(released[k - 1])`` (1 wide, else 0 strict), in
    ``settle`` and ``e2e_implausible.by_stamps`` alike: that way is written -1. None: every
    frame read by the rule."""
    if reading is None:
        return None
    rule = reading.copy()
    rule[1:][rule[1:] == released[:-1]] = -1
    return None if bool((rule == -1).all()) else rule.tobytes()
