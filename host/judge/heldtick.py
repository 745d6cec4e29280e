"""A reboot whose boot summary the bus held back past the power-up tick's window, told at its
tick's page (issue #11).

A firmware's power-up tick sends its pose of COUNTER 0, its summary (UPTIME 0, COUNTER 0) and
then a rotating page (COUNTER 1, firmware/reports.py). ``bootticks.boot_tick`` reads the summary
at its stamp: less than ``BOOT_WINDOW_MS`` (80 ms) after the pose run's COUNTER 0. A delaying
bus may hold the summary back longer and let the rest of the tick out in order. Kobuki random
696, 8 s, ``busoff=1.5:0.2,delay=0.1:150,stall=3.1:0.3,reboot=0.2:0.2``: the new firmware's pose
of COUNTER 0 and its page of COUNTER 1 heard in order at 0.401 s, its summary 150 ms late at
0.551 s (after the summary of COUNTER 2 and page 3 of 0.501 s); UPTIME said 0 in both lives,
no reboot was told and the correct firmware FAILed by ODOM_TWIST 7.83 mm/s and DISTANCE 1.0 mm
(``reboot=0.5``: 72.1 mm off).

So the summary is also read at its tick's page: an ODOM_STATUS frame of COUNTER 1 heard in
order (``livelatestatus``: it fills no hole) that breaks the status sequence against the
in-order frame heard before it (``bootticks.status_breaks``: one life gets from that COUNTER to
its page of COUNTER 1, sent in its summary of COUNTER 0's tick, no sooner than to that summary),
with a pose run of COUNTER 0 (not held back, ``liveheldpose``) heard less than ``BOOT_WINDOW_S``
before it, the run's latest COUNTER below ``BOOT_POSE_FRAMES``: the power-up tick's signature,
the page standing for the summary. The summary of COUNTER 0 heard after that page (before the
in-order sequence passed ``HELD_BACK_MAX`` steps beyond it: it may fill that hole) was sent in
the page's tick, before it: when it says UPTIME 0 it is that tick's, a reboot whose life starts
at the tick (``tick_s``: the page's bus time; ``run_s``: the pose run's start). Within one life
a page of COUNTER 1 heard in order never breaks the status sequence (its frames never come
faster than their cycle), so an old firmware's page is not taken; a page right after a frame
held back is read against the in-order frame before the hole, not against that frame (kobuki
random 696: the old life's own tick of 0.001 s, summary and page, came 150 ms late at 0.151 s).

One rule for every judge: the whole log (``tick_pages``), the streamed ``analyze`` (a
``TickPages`` carried across chunks, ``tick_pages``) and the live ones (``SourceWatch``'s
``hear_pose``, ``hear_status``).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.bootticks import (
    BOOT_POSE_FRAMES,
    BOOT_WINDOW_S,
    next_run,
    pose_rows,
    status_breaks,
    status_rows,
)
from odocan.host.judge.liveheldpose import PoseOrder
from odocan.host.judge.livelatestatus import HELD_BACK_MAX, StatusOrder
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK
from odocan.host.protocol.decode import BulkDecoder

TICK_PAGE_COUNTER = 1  # the power-up tick's rotating page: sent right after its summary
Tick = tuple[float, float]  # a held boot summary's tick: the page's bus time, the run's start


class TickPages:
    """One sender's poses (ODOM_POSE_X) and ODOM_STATUS frames (CRC holding, any sequence, bus
    order): the latest tick page that may stand for a held-back boot summary, and, for the
    ODOM_STATUS frame heard last, the tick it was sent in (``told``; module docstring)."""

    def __init__(self) -> None:
        self.status = StatusOrder()
        self.poses = PoseOrder()
        self.run: tuple[float, int, bool] | None = None  # the pose run (``next_run``)
        self.pose_s: float | None = None  # the bus time of the latest pose
        self.zero_held = False  # whether the run's pose of COUNTER 0 was held back
        self.top: tuple[float, int] | None = None  # the latest in-order ODOM_STATUS frame
        self.page: Tick | None = None  # a tick page heard, its summary not yet
        self.told: Tick | None = None  # the tick of the ODOM_STATUS frame heard last

    def hear_pose(self, t_s: float, counter: int) -> None:
        """An ODOM_POSE_X of E2E ``counter`` heard at bus time ``t_s``: on the run."""
        self.run = next_run(self.run, t_s, counter, self.pose_s)
        self.pose_s = t_s
        held = self.poses.hear(counter, t_s)
        self.zero_held = held if counter == 0 else self.zero_held

    def hear_status(self, t_s: float, counter: int) -> None:
        """An ODOM_STATUS frame (any page) of E2E ``counter`` heard at bus time ``t_s``."""
        late = self.status.hear(counter)
        self.told = None
        if counter == 0 and self.page is not None:  # the held summary of the page's tick
            self.told, self.page = self.page, None
        if late:
            return
        top, self.top = self.top, (t_s, counter)
        if self.page is not None and (counter - TICK_PAGE_COUNTER) & ENC_COUNTER_MASK > (
            HELD_BACK_MAX
        ):
            self.page = None  # past where its summary could fill a hole
        if counter == TICK_PAGE_COUNTER and self._ticked(t_s, top):
            self.page = (t_s, self.run[0]) if self.run is not None else None

    def _ticked(self, t_s: float, top: tuple[float, int] | None) -> bool:
        """Whether a page of COUNTER 1 heard in order at ``t_s`` after the in-order frame
        ``top`` is a power-up tick's (module docstring)."""
        if top is None or top[1] == TICK_PAGE_COUNTER or not status_breaks(top[1], t_s - top[0]):
            return False
        run = self.run
        return (
            run is not None
            and not self.zero_held
            and not math.isnan(run[0])
            and 0 <= run[1] < BOOT_POSE_FRAMES
            and 0.0 <= t_s - run[0] < BOOT_WINDOW_S
        )


def tick_pages(
    frames: FrameArrays,
    decoder: BulkDecoder,
    positions: npt.NDArray[np.int64],
    pages: TickPages | None = None,
) -> list[Tick | None]:
    """Per summary at ``positions`` (in order, their CRC holding): the tick of its held-back
    boot summary (``TickPages.told``), every pose and ODOM_STATUS frame of ``frames`` heard on
    ``pages`` in bus order (a stream's, carried across chunks; None: a fresh one)."""
    pages = TickPages() if pages is None else pages
    pose_at, pose_t, pose_c = pose_rows(frames, decoder)
    status_at, status_t, status_c = status_rows(frames, decoder)
    heard = sorted(
        [
            (int(p), 0, float(t), int(c))
            for p, t, c in zip(pose_at.tolist(), pose_t.tolist(), pose_c.tolist(), strict=True)
        ]
        + [
            (int(p), 1, float(t), int(c))
            for p, t, c in zip(
                status_at.tolist(), status_t.tolist(), status_c.tolist(), strict=True
            )
        ]
    )
    wanted = set(positions.tolist())
    told: dict[int, Tick | None] = {}
    for at, kind, t_s, counter in heard:
        if kind == 0:
            pages.hear_pose(t_s, counter)
            continue
        pages.hear_status(t_s, counter)
        if at in wanted:
            told[at] = pages.told
    return [told.get(int(p)) for p in positions.tolist()]


def tick_s(held_s: float | None, tick: Tick | None) -> float | None:
    """The bus time of a boot summary's tick: ``held_s`` (``heldboot.held_tick_s``: right
    behind its page) when known, else its page's (``tick``: past the next summary), else None
    (it was not held back behind its page)."""
    return held_s if held_s is not None else None if tick is None else tick[0]
