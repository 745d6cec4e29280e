"""Where exactly a replayed stall halts the firmware, and which frames its receive FIFO held
(``replay_lives``' halts, fitted to the log).

The log shows a stall as a silence of the firmware's frames, which bounds the halt only to a
tick or so at each end: the firmware sends its poses every other tick *of its own* (and its
other frames more rarely), so it may have run a silent tick after its last frames before the
halt, and, its phase shifted by the halt, a silent tick after it before its first frames. And
the board that resumed took only the first ``HW_RX_FIFO_FRAMES`` frames its CAN controller held
(``sim.board``), of every node: the encoder frames, and the motor commands, truth frames and
the like that the replay otherwise does not feed (a frame logged just after the tick before
the halt may or may not have been taken by that tick). Replayed one tick early and with only
encoder frames in the FIFO, a correct firmware departed by 20.26 mm after a 10-tick stall on a
bit-timed bus (``stall=2.015:0.105``, seed 4) and was UNJUDGED; one tick late, its poses after
the stall named no frame the replay's named and were never compared.

So each stall is tried (``fit_halts``) under every halt the silence allows (start up to a pose
period after the last frames, end up to a pose period before the first ones after it, at least
``LOST_TIME_PERIODS - 1`` ticks: the board's ``HALT_AFTER_S``) and every FIFO content the log's
frames allow, in turn, on the log up to the next stall: the one whose replayed poses are the
log's, byte for byte, wins (a wrong firmware reproduces none); else one within tolerance; else
the one comparing the most poses, so the life departs after the stall and is UNJUDGED, as
before. A trial that leaves any of the log's poses after the silence unnamed by the replay's is
never taken: out of the log's pose phase after the halt, it compares only the poses before it.
The silence as it was (the only halt replayed before) was that for ``stall=2.0:0.095`` (seed
4, instant bus): its firmware's first frames after it were no poses, the replay's poses named
none of the log's after it, and a log with ODOM_POSE_X raised 10 mm there PASSed. The silence
as it is stays only when no trial names them all (or the log has no pose after it).

The log's poses after the silence are those naming a tick from its first on, not its end: the
first pose after a 50-tick halt names the encoder frame of the halt's first tick, held by the
FIFO, whose 4-bit COUNTER resolves 48 ticks later, inside the silence (``EncoderTrack.named``).
Taken from the silence's end, two halts one tick apart (``stall=7:0.5,stall=7.52:0.5``, seed
7: ticks 700..749 and 752..801) left no pose after the first before the second: no trial was
taken, the first halt stayed one tick early with an empty FIFO, and the correct firmware was
UNJUDGED (issue #11).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np
import numpy.typing as npt

from odocan.firmware.clock import LOST_TIME_PERIODS
from odocan.host.io.logs import FrameArrays
from odocan.host.judge.analysis import Tolerance
from odocan.host.judge.replay_compare import departures, onboard_by_tick, versus_log
from odocan.host.judge.replay_lives import FIRMWARE_NODE, LifePlan
from odocan.host.judge.replay_track import EncoderTrack
from odocan.host.protocol.e2e import check_frames
from odocan.sim import contract
from odocan.sim.mcu import HW_RX_FIFO_FRAMES

Halt = tuple[int, int]
Held = tuple[tuple[int, int], ...]  # (log position, first halted tick): fed once it is due
MIN_HALT_TICKS = LOST_TIME_PERIODS - 1  # the board's HALT_AFTER_S: 9.5 periods between ticks


def pose_period_ticks() -> int:
    """How many firmware ticks apart its poses are sent (the DBC's cycle times)."""
    pose_s = contract.cycle_time_s("ODOM_POSE_X")
    return max(1, round(pose_s / contract.cycle_time_s("WHEEL_ENCODERS")))


def halt_candidates(silence: Halt) -> list[Halt]:
    """The halts a silence of the firmware's frames ([first, end) ticks: from the tick after
    the one of its last frames to the one of its next) allows, the silence itself first."""
    first, end = silence
    period = pose_period_ticks()
    found = [(s, e) for s in range(first, first + period) for e in range(end, end - period, -1)
             if e - s >= MIN_HALT_TICKS]
    return found or [silence]


def fifo_contents(frames: FrameArrays, track: EncoderTrack, halt: Halt) -> list[Held]:
    """The frames other than the accepted encoder frames that the halted board's receive FIFO
    may have held at the halt's end, one tuple per distinct FIFO content the log allows: the
    frames of other nodes logged after the encoder frame of the tick before the halt, of which
    the first ``j`` that tick may have taken (any ``j``), then the first ``HW_RX_FIFO_FRAMES``."""
    first = halt[0]
    at = int(np.searchsorted(track.tick, first))
    if at == 0 or at >= len(track.index):
        return [()]
    own = [m.frame_id for m in contract.database().messages if m.senders == [FIRMWARE_NODE]]
    span = np.arange(int(track.index[at - 1]) + 1, len(frames.can_id))
    span = span[~np.isin(frames.can_id[span], own)][: 64 + HW_RX_FIFO_FRAMES]
    before = int(np.count_nonzero(span < int(track.index[at])))
    fed = set(track.index.tolist())
    contents: list[Held] = []
    for j in range(before + 1):
        held = tuple((int(p), first) for p in span[j:j + HW_RX_FIFO_FRAMES] if int(p) not in fed)
        if held not in contents:
            contents.append(held)
    return contents


def fit_halts(frames: FrameArrays, accepted: npt.NDArray[np.bool_], track: EncoderTrack,
              plan: LifePlan, tolerance: Tolerance,
              replay: Callable[[FrameArrays, LifePlan], FrameArrays]) -> LifePlan:
    """The plan with each stall halted where, and its FIFO holding what, the log's poses say
    (module docstring), stall after stall; ``replay``: the replayed bus of a prefix of the log
    under a plan."""
    for k, silence in enumerate(plan.halts):
        cut = _next_halt_position(track, plan, k, len(frames))
        head, head_accepted = frames.select(slice(0, cut)), accepted[:cut]
        # after the halt: every pose naming a tick from the silence on (none before it does),
        # the first one's ENC_COUNTER may alias into the silence (module docstring)
        after = {t for t in onboard_by_tick(head, head_accepted) if t >= silence[0]}
        best: tuple[tuple[int, int, int], LifePlan] | None = None
        for halt in halt_candidates(silence):
            for held in fifo_contents(frames, track, halt):
                tried = _with_halt(plan, k, halt, held)
                replayed = replay(head, tried)
                named = set(onboard_by_tick(replayed, check_frames(replayed)[1]))
                if not after or not after <= named:
                    continue  # out of the log's pose phase after it: compares none there
                score = _score(versus_log(head, head_accepted, replayed), tolerance)
                if best is None or score > best[0]:
                    best = (score, tried)
        if best is not None:
            plan = best[1]
    return plan


def _score(vs: dict[str, Any], tolerance: Tolerance) -> tuple[int, int, int]:
    """How well a trial reproduced the log: 2 all its poses identical, 1 within tolerance,
    0 departing; then how many poses were compared, or, departing, how many were identical
    first. A log raised 10 mm from 0.7 s after a stall (kobuki random 701, 8 s,
    ``busoff=1.5:0.2,delay=0.1:150,stall=3.1:0.3``, from 3.8 s) departs under every trial: taken
    by the poses compared, the fit kept a FIFO under which the replay was 0.1 mm off from the
    first pose after the stall (the untampered log: identical under another), and the life was
    UNJUDGED, the stall never shown reproduced (``replay_stallkept``), where the FIFO
    reproducing the poses up to the raised ones makes it a FAIL."""
    samples, identical = int(vs["samples"]), int(vs["identical"])
    if not samples:
        return (0, 0, 0)
    if identical == samples:
        return (2, samples, identical)
    if departures(vs, tolerance):
        return (0, identical, samples)
    return (1, samples, identical)


def _with_halt(plan: LifePlan, k: int, halt: Halt, held: Held) -> LifePlan:
    """``plan`` with its stall ``k`` halted over ``halt``, its FIFO holding ``held``."""
    old = plan.halts[k]
    halts = [*plan.halts[:k], halt, *plan.halts[k + 1:]]
    kept = tuple(h for h in plan.held if h[1] != old[0] and h[1] != halt[0])
    return replace(plan, halts=halts, held=tuple(sorted(kept + held)))


def _next_halt_position(track: EncoderTrack, plan: LifePlan, k: int, n_log: int) -> int:
    """The log position up to which stall ``k`` is fitted: the next stall's or life's start."""
    ends = [n_log]
    tick = plan.halts[k][0]
    for first, _ in itertools.islice(plan.halts, k + 1, k + 2):
        ends.append(_position(track, first, n_log))
    ends += [int(track.index[s]) for s in plan.starts if int(track.tick[s]) > tick]
    return min(ends)


def _position(track: EncoderTrack, tick: int, n_log: int) -> int:
    """The log position of the encoder frame at or after ``tick`` (``n_log``: none)."""
    at = int(np.searchsorted(track.tick, tick))
    return int(track.index[at]) if at < len(track.index) else n_log
