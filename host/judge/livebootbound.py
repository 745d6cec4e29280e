"""Bounds on the frame a rebooted firmware's first count page counts back to, live (issue #11: "a
FAIL must never blame a correct firmware").

A reset, the MCU halted right after the new life's first tick with its mailbox full, and frames
held back on the bus (lockstep ``--scenario random --duration 7 --faults
reboot=2.5:0.05,stall=2.56:0.3,delay=0.2:30``, ``tests/test_reboot_halt_delay.py``): the firmware
took the frames its mailbox kept, which are not those the host's E2E sequence took in bus order
(the late ones it refused), so its first count page (``primed.counted_start``) counted back over
the live window can land anywhere. ``analyze`` PASSed every seed; the monitor and the bridge said
POSE WRONG, the life started on the wrong frame:

* seed 3 (pmir 124.9 mm, 169.7 mrad beyond; kobuki 158.5 mm): the page (ENC_E2E_OK 3,
  ENC_E2E_LOST 11) counted back to the frame of 2.80 s, after the one the power-up pose named
  (2.55 s), stepped back a lap to the frame of 2.48 s (``within_named``), which the old
  firmware's pose of 2.481 s had named, 7 frames before it. The new
  firmware's mailbox was empty at its reset: it took no frame the old firmware had taken. A count
  at or before the latest frame a sample of the old life was made of (``floor``) is wrong: the
  power-up pose's frame stands (``bounded_start``).
* seed 6 (pmir 149.7 mm, 132.0 mrad; kobuki 151.9 mm): the power-up pose was held back 30 ms,
  heard after the boot summary, so the summary did not take its word; the page (OK 10, LOST 14)
  counted back to 2.71 s, a COUNTER lap late (the halt hid 16 lost frames, ``within_named``).
  A power-up pose heard less than half an encoder COUNTER lap after the summary, naming the
  frame the summary's own rule named, is its word too (``held_named``).
* seed 12 (pmir 2.50 mm, 44.0 mrad beyond; kobuki 3.87 mm, 63.5 mrad): the frames of the new
  life's first tick were held back, its boot summary said INIT and no power-up pose followed; the
  firmware primed on the next frame it received (2.56 s: its mailbox keeps the oldest), but the
  page (OK 9, LOST 15) counted back to 2.72 s, a lap late. An INIT firmware primes on a frame
  after its summary, the earliest its mailbox kept: a count after the summary's next frame is
  stepped back whole laps while it stays at or after that frame (``after_init``).
* seed 17 (pmir 16.8 mm, 97.4 mrad beyond; ``analyze`` PASS): the power-up pose held back 30 ms
  past its summary named a COUNTER 12 held back too, heard in the summary's tick just before the
  COUNTER 15 the summary's rule named; the halt kept its count page from counting, the wait
  ended on that rule's frame (seq order: after the named one). Its word stands when the frame it
  names came less than an encoder cycle before that one, its COUNTER 0 restarting the sequence
  (``held_tick_word``); 0.062 mm (``tests/test_reboot_halt_held.py``).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import numpy.typing as npt

from odocan.host.judge.livewindow import CYCLE_S, HALF_LAP
from odocan.host.judge.primed import within_named
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK

if TYPE_CHECKING:
    from odocan.host.judge.bootnamed import LivePowerUp
    from odocan.host.judge.livepose import FramePose

HELD_POWERUP_S = HALF_LAP * CYCLE_S  # a power-up pose held back past its summary: this soon


class BootWord(NamedTuple):
    """What a waiting boot knows of its frame (``livestart.Lives``): the frame (seq) its power-up
    pose named in the summary's tick (None: none), the summary's own rule's frame, the summary's
    bus time (s), the latest frame a sample of the old life was made of (-1: none) and whether
    the summary said INIT (``unnamed`` then the frame after it)."""

    named: int | None
    unnamed: int
    summary_s: float
    floor: int
    init: bool = False


def old_life_floor(sampled: Iterable[int], guess: int) -> int:
    """The latest encoder frame (seq) before ``guess`` an on-board sample was made of when a
    reboot is told (``livehalves.HalfPairs.sampled``): the old firmware took it; -1 when none."""
    return max((seq for seq in sampled if seq < guess), default=-1)


def held_named(powerup: LivePowerUp, word: BootWord) -> int | None:
    """The frame a power-up pose heard after the summary (held back less than
    ``HELD_POWERUP_S``) names, when it is the summary's own rule's frame; else None."""
    latest = powerup.latest
    if latest is None or latest[1] is None or latest[1] != word.unnamed:
        return None
    return latest[1] if 0.0 <= latest[0] - word.summary_s < HELD_POWERUP_S else None


def held_tick_word(powerup: LivePowerUp, word: BootWord,
                   times: tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]) -> int | None:
    """The frame (seq) a power-up pose heard after the summary (held back less than
    ``HELD_POWERUP_S``, its COUNTER 0 restarting the sequence) names, when the firmware drained
    it in the summary's tick: heard less than an encoder cycle before the summary's own rule's
    frame (``times``: the window's seqs and bus times); else None (module docstring, seed 17)."""
    pose = powerup.restarted_at
    if pose is None or not 0.0 <= pose[0] - word.summary_s < HELD_POWERUP_S:
        return None
    seqs, t_s = times
    named, unnamed = np.flatnonzero(seqs == pose[1]), np.flatnonzero(seqs == word.unnamed)
    if not len(named) or not len(unnamed) or pose[1] > word.unnamed:
        return None
    return pose[1] if float(t_s[unnamed[0]] - t_s[named[0]]) < CYCLE_S else None


def bounded_start(encoders: tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]], at: int,
                  word: BootWord, powerup: LivePowerUp) -> int:
    """A count page's frame ``at`` bounded by the boot's power-up pose's word (module docstring):
    no later than it (``primed.within_named``: whole laps back), and that frame itself when the
    count lands at or before the old life's ``floor``; ``at`` when no power-up pose named one."""
    named = word.named if word.named is not None else held_named(powerup, word)
    if named is None:
        return after_init(encoders, at, word.unnamed) if word.init else at
    stepped = within_named(encoders, at, named)
    return named if stepped <= word.floor < named else stepped


def after_init(encoders: tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]], at: int,
               earliest: int) -> int:
    """A count page's frame ``at`` of a firmware whose boot summary said INIT, stepped back
    whole COUNTER laps to the earliest frame of its COUNTER at or after ``earliest`` (the
    frame after the summary: it primed on one it received after, a halt hiding whole laps
    from its ENC_E2E_LOST); ``at`` when none is there."""
    positions, counter = encoders
    i = int(np.searchsorted(positions, at))
    if at <= earliest or i >= len(positions) or positions[i] != at:
        return at
    same = np.flatnonzero((positions >= earliest) & (positions < at)
                          & ((counter - counter[i]) & ENC_COUNTER_MASK == 0))
    return int(positions[same[0]]) if len(same) else at


def power_up_pose(pose: FramePose) -> bool:
    """Whether ``pose`` is a power-up pose, (0, 0, 0): at the frame its life primed on."""
    return pose.x_m == 0.0 and pose.y_m == 0.0 and pose.heading_rad == 0.0
