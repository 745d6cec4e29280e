"""The poses sent right after a stall's first one, before the next sample (issue #11, rule 5).

After a stall the firmware works off its backlog: its first pose names a frame of the backlog,
and the next ones may name frames whose ENC_COUNTER ``match_encoder`` cannot resolve either
(kobuki random seed 3, ``stall=3:0.3``: the poses at 3.301 s and 3.321 s both name ENC_COUNTER
12, the first the backlog's frame of 3.00 s, the second the live one of 3.32 s). Neither is a
sample; only the first is the silence's (``stallfirst.judge_left_out``), so the second went
unjudged and +1 m on both PASSed ``analyze`` whole and streamed. The poses between the
silence's first and the next kept sample are judged by the same neighbours (the last sample
before the silence, the first after) as the first one: the stall is the firmware's own (the
log heard every encoder frame through it, ``stallfirst.heard_through``), never a recorder's
gap, whose poses stay with the gap rules."""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol, TypeVar

FOLLOW_ON_POSES = 4  # at most this many poses after the silence's first are its followers

P_co = TypeVar("P_co", covariant=True)


class PairsAt(Protocol[P_co]):
    """``stallfirst._Pairs``: the pose of an ODOM_POSE_X index, and how many there are."""

    count: int

    def at(self, k: int) -> P_co | None: ...


def follow_ons(pairs: PairsAt[P_co], is_kept: Callable[[P_co], bool], k: int,
               silent: set[int]) -> list[P_co]:
    """The poses of the ODOM_POSE_X indices after ``k`` (a silence's first pose) up to the first
    kept sample or the next silence's first pose (``silent``), at most ``FOLLOW_ON_POSES``, that
    are whole (both halves) and no sample: the poses the backlog's work-off left unresolved."""
    found: list[P_co] = []
    for j in range(k + 1, min(k + 1 + FOLLOW_ON_POSES, pairs.count)):
        if j in silent:
            break
        pose = pairs.at(j)
        if pose is None:
            continue
        if is_kept(pose):
            break
        found.append(pose)
    return found
