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

A new firmware up in the old life's COUNTER phase breaks no sequence (kobuki and pmir random
692, 696, 700 ``reboot=0.5:0.3,delay=0.1:150``: up at 0.801 s, its page of COUNTER 1 400 ms
after the old COUNTER 9, its pose of COUNTER 0 320 ms after the old 8; its summary heard at
0.951 s): the twists' DISTANCE that fell in the pose run before the page (``told_tick``'s
``fell``: ``bootticks.fell_in_run`` read at the page, ``boot_tick``'s second evidence) tells it
as well; no judge told a reboot and the correct firmware FAILed (2.654 .. 81.09 mm beyond a
resume). A summary of COUNTER 0 held back with its page (or its page lost) is dated by the
in-order frame it fills a hole before (``dated_tick``) and needs that fall too. A page whose
summary comes ``HELD_S`` or more after it is not its tick's (a joint wrap's page of the old
life, 9.6 s, stood for a boot summary at 10.3 s).

One rule for every judge: the whole log (``tick_pages``), the streamed ``analyze`` (a
``TickPages`` carried across chunks, ``tick_pages``) and the live ones (``SourceWatch``'s
``hear_pose``, ``hear_status``); the offline ones read ``told_tick`` before ``observe``.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.bootticks import (
    BOOT_POSE_FRAMES,
    BOOT_WINDOW_S,
    STATUS_FRAMES_PER_CYCLE,
    next_run,
    pose_rows,
    status_breaks,
    status_rows,
)
from odocan.host.judge.liveheldpose import PoseOrder
from odocan.host.judge.livelatestatus import HELD_BACK_MAX, StatusOrder
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK, STATUS_CYCLE_S
from odocan.host.protocol.decode import BulkDecoder

TICK_PAGE_COUNTER = 1  # the power-up tick's rotating page: sent right after its summary
# a summary heard this long after its tick's page or later is not that tick's (it fills no hole)
HELD_S = HELD_BACK_MAX * STATUS_CYCLE_S / STATUS_FRAMES_PER_CYCLE
STAMP_S = 1e-6  # a log's stamp resolution: a dated send read no sooner than its tick's frames
# a held boot summary's tick: the page's bus time, the run's start, whether the page broke the
# status sequence (else the twists' DISTANCE must have fallen in the run: ``fell``)
Tick = tuple[float, float, bool]


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
        self.fell: bool | None = None  # a log's: whether DISTANCE fell in its run (None: live)

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
            self.told, self.page = (self.page if t_s - self.page[0] < HELD_S else None), None
        elif counter == 0 and late and self.top is not None:  # dated by the frames after it
            self.told = dated_tick(self.top)
        if late:
            return
        top, self.top = self.top, (t_s, counter)
        if self.page is not None and (counter - TICK_PAGE_COUNTER) & ENC_COUNTER_MASK > (
            HELD_BACK_MAX
        ):
            self.page = None  # past where its summary could fill a hole
        if counter == TICK_PAGE_COUNTER and self._in_run(t_s):
            self.page = (t_s, self.run[0], self._broke(t_s, top)) if self.run else None

    @staticmethod
    def _broke(t_s: float, top: tuple[float, int] | None) -> bool:
        """Whether a page of COUNTER 1 heard in order at ``t_s`` after the in-order frame
        ``top`` breaks the status sequence (module docstring)."""
        return (
            top is not None and top[1] != TICK_PAGE_COUNTER and status_breaks(top[1], t_s - top[0])
        )

    def _in_run(self, t_s: float) -> bool:
        """Whether a pose run of COUNTER 0, not held back, began less than ``BOOT_WINDOW_S``
        before ``t_s``, its latest COUNTER below ``BOOT_POSE_FRAMES``."""
        run = self.run
        return (
            run is not None
            and not self.zero_held
            and not math.isnan(run[0])
            and 0 <= run[1] < BOOT_POSE_FRAMES
            and 0.0 <= t_s - run[0] < BOOT_WINDOW_S
        )


def dated_tick(top: tuple[float, int]) -> Tick:
    """The tick of a summary of COUNTER 0 held back behind the in-order ODOM_STATUS frame
    ``top`` (bus time, COUNTER: it fills a hole of the sequence, ``livelatestatus``), its page
    of COUNTER 1 held back too or lost: sent ``top``'s COUNTER's cycles before it (two frames a
    cycle, the summary first; lost frames take no time away, a stall makes it sooner), its
    page not read (it broke nothing). Kobuki random 692 ``reboot=0.5:0.3,delay=0.1:150``: the
    new firmware's power-up pose, summary and page sent at 0.801 s all heard at 0.951 s, after
    the page of COUNTER 3 of 0.901 s; its twist of COUNTER 0 at 0.801 s, DISTANCE 0 where the
    old life's read 85 mm, was heard in order (``told_tick``'s ``fell``)."""
    sent_s = top[0] - (top[1] // STATUS_FRAMES_PER_CYCLE) * STATUS_CYCLE_S + STAMP_S
    return sent_s, sent_s, False


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


def told_tick(tick: Tick | None, fell: Callable[[float], bool]) -> Tick | None:
    """``tick`` when it tells a power-up tick: its page broke the status sequence, or ``fell``
    (the twists' DISTANCE fell in the pose run before the page, read at its bus time:
    ``bootticks.fell_in_run``, as ``boot_tick``'s ``fell``); else None."""
    return tick if tick is not None and (tick[2] or fell(tick[0])) else None
