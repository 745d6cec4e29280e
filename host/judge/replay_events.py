"""When a replay feeds a log's frames (``host.judge.replay.LockstepReplay.run``): the order of
the events, the encoder frames the host refused and the tick each reached the firmware, the truth
frames only the firmware's receive queue gets, and the log's clock steps taken out."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.sim import contract

IntArray = npt.NDArray[np.int64]
CLOCK_STEP_S = 1.0  # a log's time going back further than this: its recorder's clock was set back


def late_ticks(late: IntArray, tick: IntArray, phase_ticks: int, n_frames: int,
               held: dict[int, int]) -> dict[int, int]:
    """Log position -> replay tick of each encoder frame the host's E2E check refused
    (``replay_track.late_frames``), ``phase_ticks`` later, less those past the end of the
    frames (a prefix of the log, tried) and those a halted board's FIFO held (fed as such)."""
    return {int(p): int(t) + phase_ticks for p, t in zip(late.tolist(), tick.tolist(), strict=True)
            if int(p) < n_frames and int(p) not in held}


def clock_steps_s(timestamp_s: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """What to add to each logged time so that a recorder's clock set back mid-log (the time
    going back more than ``CLOCK_STEP_S`` from one frame to the next) does not take the replayed
    bus back with it: the frames after such a step go on one median frame spacing after the
    frame before it. Without it the log's frames after the step reached the replayed bus 100 s
    "before" the replayed firmware's poses naming them, which were then never paired (the trial:
    416 of 1000 poses compared, a firmware 1 mm off PASSed). Zero for a log whose time never
    goes back that far (a frame late on the bus goes back by less than a cycle)."""
    times = np.asarray(timestamp_s, dtype=np.float64)
    if len(times) < 2:
        return np.zeros(len(times))
    gaps = np.diff(times)
    forward = gaps[gaps > 0]
    spacing = float(np.median(forward)) if len(forward) else 0.0
    steps = np.where(gaps < -CLOCK_STEP_S, spacing - gaps, 0.0)
    return np.concatenate(([0.0], np.cumsum(steps)))


def unfed_truth(frames: FrameArrays, truth: IntArray, held: dict[int, int]) -> set[int]:
    """The held frames that are truth frames left off the replayed bus (a log whose firmware
    powered up mid-drive: ``truth_compared`` False): handed to the firmware's receive queue
    alone, since the halted board's FIFO held them (three slots: ``stall=0:1,stall=6:0.5``,
    seed 2, kept the MOTOR_CMD, the encoder frame and the first SIM_TRUTH frame of the halt's
    first tick); left out, the replay's FIFO took a later encoder frame in its place, no
    trial reproduced the log, and the correct firmware was UNJUDGED (issue #11)."""
    truth_id = contract.database().get_message_by_name("SIM_TRUTH").frame_id
    fed = set(truth.tolist())
    return {p for p in held if p not in fed and int(frames.can_id[p]) == truth_id}


def fed_events(encoders: IntArray, truth: IntArray, held: dict[int, int] | None = None,
               late: dict[int, int] | None = None) -> list[tuple[int, int]]:
    """(position in the log, k) in log order: k the encoder frame's number, -1 for truth, -2
    for a frame a halted board's FIFO held (``LockstepReplay.held``; a truth frame not fed
    goes to the firmware alone: ``unfed_truth``), -3 for an encoder frame the host's E2E check
    refused (``late``: ``late_ticks``)."""
    held = held or {}
    events = [(int(p), k) for k, p in enumerate(encoders.tolist())]
    events += [(int(p), -1) for p in truth.tolist() if int(p) not in held]
    events += [(p, -2) for p in held]
    events += [(p, -3) for p in (late or {})]
    events.sort()
    return events


def replayed_positions(log: FrameArrays, index: IntArray, replayed: FrameArrays) -> IntArray:
    """The position on the replayed bus of each log frame at ``index`` (encoder frames, in log
    order), matched by identifier, payload and time (the log's, less its clock steps:
    ``clock_steps_s``), in order; ``len(replayed)`` for one not found (not fed). Not by the
    host's E2E verdicts on the replayed bus: they read its poses too, which the replayed firmware
    sent, so its accepted encoder frames were not the log's (984 for 976, ``delay=0.3:50,
    busoff=5:1,reboot=12,dup=0.1``, pmir seed 1) and a life's span on it started 9 frames
    early: its poses were paired with the life before's, 5827.7 mrad off."""
    shift = clock_steps_s(log.timestamp_s)
    want = [(int(log.can_id[p]), bytes(log.data[p]), round(float(log.timestamp_s[p] + shift[p]), 6))
            for p in index.tolist()]
    where: dict[tuple[int, bytes, float], list[int]] = {}
    for p in np.flatnonzero(np.isin(replayed.can_id, [w[0] for w in want])).tolist()[::-1]:
        key = (int(replayed.can_id[p]), bytes(replayed.data[p]),
               round(float(replayed.timestamp_s[p]), 6))
        where.setdefault(key, []).append(p)  # latest first: popped from the end in order
    result = np.full(len(want), len(replayed), dtype=np.int64)
    last = -1
    for k, key in enumerate(want):
        found = where.get(key, [])
        while found and found[-1] <= last:
            found.pop()
        if found:
            result[k] = last = found.pop()
    return result
