"""A life's first pose made a COUNTER lap or more after the frame it names (issue #11: a FAIL
must never blame a correct firmware; a PASS must never hide a wrong pose).

A firmware still starting when the robot's frames began (its mailbox overflowing: its
FRAME_TOTALS count the frames it lost) integrates the frames it kept and sends its first pose
naming the latest it took by the 4-bit ENC_COUNTER; that frame may lie 16 frames or more before
the newest of that COUNTER on the bus, which the plain rule (``samples.match_encoder``) pairs
the name with. Captured (tests/files/restart_lagged_first_pose.blf): the first pose fits encoder
frame 53 within 0.02 mm, the judges took frame 73 (16 later): 79.6 mm off, a FAIL of a correct
firmware. The name cannot tell the laps apart; the pose can, as ``floodnames`` tells a flood's.

The rule, for the life's first pose only (no pose before it anchors the laps, but the life's
start does: its pose at its first encoder frame, (0, 0, 0) or the set-pose's): the frames a
pose naming ``n`` may mean are ``n`` and each a COUNTER lap before it, back to the life's first
frame (``lap_candidates``). The pose at each is the start carried over the counts
(``reference.integrate``): the candidate is taken when the pose's X and Y halves, its heading
and the same tick's ODOM_TWIST DISTANCE all lie within ``MATCH_LSB`` wire LSBs of an older
candidate's and not of the newest's (``older_lap``); else the plain name stands (the newest
fits too: it is judged there and passes). Several older ones fitting are one pose (DISTANCE,
the path length, grows with any motion: they fit each other only when the robot stood still
between them): the newest of them, as the candidates rule (``candidates``) judges a pose at any
frame it fits, never at the newest frame that FAILs it; older ones that differ: untold, the
plain name. The Y half and the twist then follow the X half's rename
(``floodnames.follow``, through ``Encoders.renamed``).

Not after a stall before that pose (``stalls.first_after_stall``: the firmware talked, then
fell silent while the frames went on, its first pose drawn from the FIFO's backlog): that life
is the stall rules' (``after_stalls`` leaves the pose out and places the reference again at the
frame it primed on, ``stallreprime`` re-primes it), which judge it soundly; moving its name as
well re-placed the reference twice and FAILed correct firmwares (the re-prime sweeps: 12.6 mrad
on the spin, 2.7 mm on the square: the backlog pose of the life's first frame, 25 laps back).

Nor when the pose is the life's start itself (X, Y, heading, DISTANCE 0: ``at_start``): a
firmware that primed late, on the very frame its name means (a power-up stall the MCU never ran
through, ``stall=0:1``), says that too, and near a start at rest an older lap fits it as well;
the plain name stands (``powerup``'s rules judge a late prime). Measured: the streamed judge
refused ``test_faults_mcu``'s late power-up (its heading 0 and DISTANCE fit frame 4, from
(0, 0, 0) at frame 0, the newest frame 100 off by 327 mm of DISTANCE).

Why a wrong firmware gains nothing: a pose 10 mm off fits no candidate and keeps its newest
name (a FAIL, as before); a pose excused by an older lap is right there in all four quantities
(two positions, the heading, the path length), each to a couple of LSBs: what a correct firmware
that integrated that frame last says, and what a wrong one matches only by a chance of about
(4 / 10000) per quantity. The frames after it are judged by the next poses as before."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.floodnames import of_robot
from odocan.host.judge.primedlap import primed_candidate
from odocan.host.judge.reference import Geometry, integrate, wrap_delta
from odocan.host.judge.samples import (
    HEADING_LSB_RAD,
    POSITION_LSB_M,
    WIRE_COUNTER_BITS,
    AnalysisError,
    Encoders,
    PoseHalves,
    accepted_rows,
    encoder_frames,
    flood_named,
    pose_halves,
)
from odocan.host.judge.stalls import first_after_stall, signs_of_life
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP
from odocan.host.protocol.decode import BulkDecoder
from odocan.sim.robot import RobotProfile

MATCH_LSB = 2.0  # wire LSBs: the pose's truncation, the firmware's integer steps, a margin
DISTANCE_LSB_M = 1e-3  # ODOM_TWIST DISTANCE: 1 mm per LSB
Start = tuple[float, float, float]  # the life's pose at its first encoder frame
REFUSAL = ("the life's first pose fits a frame a COUNTER lap before the newest of its "
           "ENC_COUNTER (lapfirst)")


class Said(NamedTuple):
    """What the firmware said of one tick: X, Y (m), heading (rad, turns included), the path
    length (m; None: no twist of that tick heard)."""

    x_m: float
    y_m: float
    heading_rad: float
    distance_m: float | None


def lap_candidates(seq: npt.NDArray[np.int64], named: int) -> list[int]:
    """The encoder frames (indices) a name ``named`` may mean: itself, then each a COUNTER lap
    before it that the log holds, back to the life's first frame (index 0)."""
    out = [named]
    s = int(seq[named]) - ENC_COUNTER_LAP
    while s >= int(seq[0]):
        k = int(np.searchsorted(seq, s))
        if k < len(seq) and int(seq[k]) == s:
            out.append(k)
        s -= ENC_COUNTER_LAP
    return out


def fits(said: Said, ref: Said) -> bool:
    """Whether ``said`` lies within ``MATCH_LSB`` LSBs of ``ref`` in each quantity (the
    heading modulo a turn; DISTANCE modulo its 65.536 m wrap)."""
    if max(abs(said.x_m - ref.x_m), abs(said.y_m - ref.y_m)) > MATCH_LSB * POSITION_LSB_M:
        return False
    if abs(math.remainder(said.heading_rad - ref.heading_rad, 2 * math.pi)) > (
            MATCH_LSB * HEADING_LSB_RAD):
        return False
    if said.distance_m is None or ref.distance_m is None:
        return said.distance_m is None  # a twist heard must fit; none heard: the pose alone
    off_m = math.remainder(said.distance_m - ref.distance_m, 65536 * DISTANCE_LSB_M)
    return abs(off_m) <= MATCH_LSB * DISTANCE_LSB_M


def older_lap(said: Said, at_candidates: list[Said]) -> int | None:
    """The position in ``at_candidates`` (the reference at ``lap_candidates``, newest first) of
    the older lap ``said`` fits when the newest does not (the newest of several that are one
    pose); None else (module docstring)."""
    if not at_candidates or fits(said, at_candidates[0]):
        return None
    hits = [k for k, ref in enumerate(at_candidates) if k and fits(said, ref)]
    if not hits or not all(fits(at_candidates[k], at_candidates[hits[0]]) for k in hits[1:]):
        return None
    return hits[0]


def reference_at(enc: Encoders, frames_at: list[int], start: Start, robot: RobotProfile,
                 integrator: str) -> list[Said]:
    """The life's start (``start``: its pose at encoder frame 0) carried to each of
    ``frames_at``: X, Y, heading and the path length (``reference.integrate``)."""
    last = max(frames_at)
    bits = min(robot.counter_bits, WIRE_COUNTER_BITS)
    path = integrate(wrap_delta(np.diff(enc.left[: last + 1]), bits),
                     wrap_delta(np.diff(enc.right[: last + 1]), bits), Geometry.of(robot),
                     integrator, x0_m=start[0], y0_m=start[1], heading0_rad=start[2])
    out = []
    for c in frames_at:
        if c == 0:
            out.append(Said(start[0], start[1], start[2], 0.0))
        else:
            out.append(Said(float(path.x_m[c - 1]), float(path.y_m[c - 1]),
                            float(path.heading_rad[c - 1]), float(path.distance_m[c - 1])))
    return out


def lap_named(frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder,
              enc: Encoders, life: tuple[RobotProfile, str, Start | None]
              ) -> tuple[Encoders, PoseHalves]:
    """``samples.flood_named``, then the life's first pose taken to the older lap its values
    fit (module docstring; ``life``: the robot, the integrator, the set-pose's start or None:
    (0, 0, 0)); ``enc`` carries the rename (``Encoders.renamed``) and every frame of that tick
    follows."""
    robot, integrator, start = life
    enc, halves = flood_named(frames, accepted, decoder, enc, of_robot(robot))
    first = _first_pose(frames, accepted, decoder, enc, halves)
    if first is None:
        return enc, halves
    i, said = first
    if said.distance_m is None:
        return enc, halves  # the tick's twist unheard: not told whole, the plain name stands
    if after_stall(frames, accepted, decoder, enc, float(halves.px["timestamp_s"][i])) or (
            at_start(said, start or (0.0, 0.0, 0.0))):
        return enc, halves  # the stall rules', or a late prime's (module docstring)
    named = int(halves.ex[i])
    cands = lap_candidates(enc.seq, named)
    if len(cands) < 2:
        return enc, halves
    found = older_lap(said, reference_at(enc, cands, start or (0.0, 0.0, 0.0), robot,
                                         integrator))
    if found is None and start is None:  # primed after the life's first frame (primedlap)
        found = primed_candidate(said, enc, cands, robot, integrator)
    if found is None:
        return enc, halves
    px = halves.px
    one = (np.array([named], dtype=np.int64), np.array([cands[found]], dtype=np.int64),
           px["ENC_COUNTER"][i:i + 1].astype(np.int64),
           px["timestamp_s"][i:i + 1].astype(np.float64))
    if enc.renamed is not None:  # a flood's renames first (``floodnames``)
        was = enc.renamed
        one = (np.concatenate((was[0], one[0])), np.concatenate((was[1], one[1])),
               np.concatenate((was[2], one[2])), np.concatenate((was[3], one[3])))
    enc = replace(enc, renamed=one)
    return enc, pose_halves(frames, accepted, decoder, enc)


def at_start(said: Said, start: Start) -> bool:
    """Whether ``said`` is the life's start itself (its X, Y, heading; DISTANCE 0): what a
    firmware that primed on the frame its name means says too (module docstring)."""
    return fits(said, Said(start[0], start[1], start[2], 0.0))


def after_stall(frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder,
                enc: Encoders, sent_s: float) -> bool:
    """Whether the pose sent at ``sent_s`` came after a stall (``stalls.first_after_stall``
    on the firmware's signs of life: its ODOM_STATUS and pose halves)."""
    pose_sent_s, alive_s = signs_of_life(frames, accepted, decoder)
    alive = np.sort(np.concatenate((alive_s, pose_sent_s)))
    return first_after_stall(sent_s, enc, alive) is not None


def _first_pose(frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder,
                enc: Encoders, halves: PoseHalves) -> tuple[int, Said] | None:
    """The life's first ODOM_POSE_X naming a frame (its row) and what its tick said: its Y half
    and twist are the first of its ENC_COUNTER naming the same frame less than a cycle after it;
    None without a Y half so (the pose alone cannot be told whole)."""
    named_x = np.flatnonzero(halves.ex >= 0)
    if not len(named_x) or enc.cycle_s is None:
        return None
    i = int(named_x[0])
    px, py = halves.px, halves.py
    t_s, counter = float(px["timestamp_s"][i]), int(px["ENC_COUNTER"][i])
    window_s = (enc.cycle_s, _tick_window_s(px["timestamp_s"], i, enc.cycle_s))
    j = _same_tick(py["timestamp_s"], py["ENC_COUNTER"], t_s, counter, window_s,
                   halves.ey == halves.ex[i])
    if j is None:
        return None
    try:
        twist = accepted_rows(frames, accepted, decoder, "ODOM_TWIST")
    except AnalysisError:
        twist = None
    k = None if twist is None else _same_tick(twist["timestamp_s"], twist["ENC_COUNTER"], t_s,
                                              counter, window_s, None)
    heading = (float(py["TURNS"][j]) * 2 * math.pi
               + float(px["HEADING"][i]) * HEADING_LSB_RAD)
    distance = None if twist is None or k is None else float(twist["DISTANCE"][k]) * (
        DISTANCE_LSB_M)
    return i, Said(float(px["X"][i]) * POSITION_LSB_M, float(py["Y"][j]) * POSITION_LSB_M,
                   heading, distance)


def _tick_window_s(x_s: npt.NDArray[np.float64], i: int, cycle_s: float) -> float:
    """How far from the X half at row ``i`` its tick's other frames may be heard: a cycle, or
    up to the next X half when that comes later. A first tick that drained a backlog of 79
    frames on a loaded machine sent its Y half and twist 17.7 ms after its X (the next X 32 ms
    after it; ``backlog_first_tick_b5.log``): within one 10 ms cycle the pose went untold and
    its name, 32 frames late, FAILed the correct firmware by 58.8 mm."""
    if i + 1 >= len(x_s):
        return cycle_s
    return max(cycle_s, float(x_s[i + 1]) - float(x_s[i]))


def _same_tick(t_s: npt.NDArray[np.float64], counters: npt.NDArray[np.int64], at_s: float,
               counter: int, window: tuple[float, float], also: npt.NDArray[np.bool_] | None
               ) -> int | None:
    """The first row of ``counter`` less than ``window`` (before, after: s) from ``at_s`` (and
    ``also``)."""
    off_s = np.asarray(t_s) - at_s
    near = (np.asarray(counters) == counter) & (off_s > -window[0]) & (off_s < window[1])
    if also is not None:
        near &= also
    rows = np.flatnonzero(near)
    return int(rows[0]) if len(rows) else None


def lagged(frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder,
           robot: RobotProfile) -> bool:
    """Whether the first pose of a life (``frames``: its first frames, up to that pose's tick)
    may be taken to an older lap (``lap_named``): its heading and DISTANCE, which no integrator
    changes, fit an older lap from (0, 0, 0) and not the newest. The streamed judge reads such a
    life whole (``stream_first``: it names a pose by the plain rule alone)."""
    enc = encoder_frames(frames, accepted, decoder)
    if not len(enc.seq):
        return False
    enc, halves = flood_named(frames, accepted, decoder, enc, of_robot(robot))
    first = _first_pose(frames, accepted, decoder, enc, halves)
    if first is None or first[1].distance_m is None:
        return False
    i, said = first
    if after_stall(frames, accepted, decoder, enc, float(halves.px["timestamp_s"][i])) or (
            at_start(said, (0.0, 0.0, 0.0))):
        return False  # the stall rules', or a late prime's (module docstring): streamed too
    cands = lap_candidates(enc.seq, int(halves.ex[i]))
    if len(cands) < 2:
        return False
    refs = reference_at(enc, cands, (0.0, 0.0, 0.0), robot, "exact")
    return older_lap(said, [r._replace(x_m=said.x_m, y_m=said.y_m) for r in refs]) is not None \
        or primed_candidate(said, enc, cands, robot, "exact", heading_only=True) is not None
