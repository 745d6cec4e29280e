"""Encoder frames the poses prove the firmware did not integrate, which its E2E check took all
the same (its plausibility bound refused the step), for ``host.protocol.e2e_evidence.settle``
(issue #11: a FAIL must never blame a correct firmware).

A pose's ENC_COUNTER names the frame the firmware integrated last, so a frame it skipped
(``pose_evidence``'s ``skipped``) was refused by the E2E check *or* taken by it and refused by the
plausibility bound (``firmware.encoders``: a step beyond the robot's maximum wheel speed over its
periods). The second moves the E2E check's last COUNTER on to that frame; ``settle`` reads a proof
of a skip as the first, but where the readings' one window takes the frame after one the firmware's
check took last (``e2e_evidence._bound_skip``). On pmir figure8, seed 82,
``delay=0.3:55,busoff=1:1``: after the 1 s bus-off the firmware took COUNTER 3, then the frames
sampled at the recovery, COUNTER 9 and 15 a lap and 6 periods on, passed its E2E window (6 periods)
and were refused by the bound (their step read over 6 periods where 22 passed), so it refused the
on-time 4, 5 and 7 (WRONG SEQUENCE from 9 and 15) and took the late COUNTER 2 (3 on from 15). The
host refused 9 as the poses' skip, took 4, 5 and 7 (a step back in counts from them), and then 2,
which the poses prove taken, as a lap on from 7: its reference stepped back and forth through a
frame 11 periods off, ODOM_TWIST DISTANCE 24.5 mm off a right firmware.

The sign: the poses prove a frame taken that every window refuses from the host's last frame,
and ``e2e_retract.firmware_last`` finds no frame the host took that the firmware could have
taken last. The frames from the last frame the poses prove taken up to it are then judged by the
stamps alone (``by_stamps``: each skip proof read as the bound's); kept where that takes a
frame the poses prove skipped and brings the proven frame within its window. The reference
refuses those frames' steps by the same bound as the firmware (``reference_path``): they move
only the E2E check's COUNTER, as on board.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from odocan.host.protocol.busfacts import ENC_COUNTER_MASK

COUNTER_MASK = ENC_COUNTER_MASK  # 0x0F
MAX_WINDOW = ENC_COUNTER_MASK  # 15: Profile 2's widest window, a lap less one
S_OK, S_LOST, S_REPEATED, S_WRONG = range(4)  # ``host.protocol.e2e``'s status codes


@dataclass(frozen=True)
class Readings:
    """One message's frames as ``settle`` reads them: CRC right, COUNTER, each reading's
    receive periods (strict, wide, narrow), the reading chosen per frame (-1: by ``late``),
    after a recorder's release (``late``)."""

    ok: Sequence[bool]
    counters: Sequence[int]
    columns: Sequence[Sequence[int]]
    chosen: Sequence[int]
    late: Sequence[bool]
    max_delta_init: int


@dataclass(frozen=True)
class Retaken:
    """``by_stamps``' verdicts: the place in ``taken`` of the last frame the poses prove
    taken, the frames taken after it up to ``j`` (not ``j``), and the status of every frame
    with a right CRC between (frame: code)."""

    place: int
    taken: list[int]
    codes: dict[int, int]


def by_stamps(j: int, taken: Sequence[int], proven: frozenset[int], skipped: frozenset[int],
              frames: Readings) -> Retaken | None:
    """The frames between the last of ``taken`` (the host's, oldest first) that the poses
    prove taken (``proven``) and frame ``j`` (proven taken, every window refusing it from the
    host's last, no frame the host took leading to it) judged by the stamps' windows alone, as
    if no pose spoke (module docstring); None unless that takes a frame proven ``skipped`` and
    brings ``j`` within the widest window of its last frame."""
    place = next((k for k in range(len(taken) - 1, -1, -1) if taken[k] in proven), None)
    if place is None:
        return None
    p = taken[place]
    windows = [frames.max_delta_init] * 3
    last = frames.counters[p]
    got: list[int] = []
    codes: dict[int, int] = {}
    for q in range(p + 1, j + 1):
        windows = [min(w + c[q], MAX_WINDOW) for w, c in zip(windows, frames.columns,
                                                              strict=True)]
        if not frames.ok[q]:
            continue
        delta = (frames.counters[q] - last) & COUNTER_MASK
        if q == j:
            usable = 0 < delta <= max(windows) and any(g in skipped for g in got)
            return Retaken(place, got, codes) if usable else None
        if q in proven:
            return None  # (none comes between: a proven frame is always taken)
        which = frames.chosen[q] if frames.chosen[q] >= 0 else int(frames.late[q - 1])
        code = (S_REPEATED if delta == 0 else S_OK if delta == 1
                else S_LOST if delta <= windows[which] else S_WRONG)
        codes[q] = code
        if code in (S_OK, S_LOST):
            got.append(q)
            last, windows = frames.counters[q], [frames.max_delta_init] * 3
    return None
