"""A wrong Python firmware for the judges' tests: the right one, with one edit of its odometry
made at the encoder step it takes after a frame its E2E receiver accepted under a trigger (after
a lock-out, the n-th lock-out, the n-th gap ...).

The firmware's own record (its receiver's statuses), which the judges never see: they read the
bus. Used by test_lockout_fill, test_live_jitter_lockout, test_twist_jitter_distance and
test_gap_step, which differ only in the trigger and the edit.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import pytest

import odocan.firmware.e2e as fw_e2e
import odocan.firmware.odometry as odometry

LOCKED_OUT = 4  # refusals in a row that only a lock-out makes (a frame held back: one)
TAKEN = (fw_e2e.E2EStatus.OK, fw_e2e.E2EStatus.OKSOMELOST)


@dataclass
class Taken:
    """The encoder receiver's record at a frame it took (``status`` OK or OKSOMELOST):
    ``refused`` the frames refused in a row just before it, ``lock_outs`` the frames taken after
    ``LOCKED_OUT`` or more refusals so far (this one counted), ``gaps`` the OKSOMELOST frames
    so far (this one counted), ``done`` the edits made so far."""

    status: fw_e2e.E2EStatus
    refused: int = 0
    lock_outs: int = 0
    gaps: int = 0
    done: int = 0


Trigger = Callable[[Taken], bool]
Edit = Callable[[odometry.Odometry], None]


def after_lock_outs(taken: Taken) -> bool:
    """Every frame taken after ``LOCKED_OUT`` or more refusals in a row (a lock-out)."""
    return taken.refused >= LOCKED_OUT


def after_lock_out(nth: int) -> Trigger:
    """The frame taken after the ``nth`` lock-out (1: the first)."""
    return lambda taken: taken.refused >= LOCKED_OUT and taken.lock_outs == nth


def after_gap(nth: int) -> Trigger:
    """The ``nth`` frame taken as OKSOMELOST (a gap)."""
    return lambda taken: taken.status == fw_e2e.E2EStatus.OKSOMELOST and taken.gaps == nth


def x_added(lsb_q40: int) -> Edit:
    """``lsb_q40`` (Q40 m) added to X."""

    def edit(odo: odometry.Odometry) -> None:
        odo.x_q40_m += lsb_q40

    return edit


def distance_taken_off(mm: int) -> Edit:
    """``mm`` mm taken off DISTANCE."""

    def edit(odo: odometry.Odometry) -> None:
        odo.distance_q40_m -= (mm << 40) // 1000

    return edit


@contextmanager
def edited_after(trigger: Trigger, edit: Edit, *, sticky: bool = True) -> Iterator[list[int]]:
    """The Python firmware, but ``edit`` made at the encoder step it takes after a frame taken
    for which ``trigger`` holds; yields [edits made]. ``sticky``: an armed edit waits for the
    next step whatever is taken meanwhile; else every frame taken re-arms or drops it."""
    check, step = fw_e2e.E2EReceiver.check, odometry.Odometry.step_deltas
    record, pending, done = Taken(fw_e2e.E2EStatus.OK), [False], [0]

    def checked(self: fw_e2e.E2EReceiver, frame: bytes | bytearray | None) -> fw_e2e.E2EStatus:
        status = check(self, frame)
        if self.window_per_period and frame is not None:  # the encoder receiver's
            if status in TAKEN:
                record.status, record.done = status, done[0]
                record.lock_outs += record.refused >= LOCKED_OUT
                record.gaps += status == fw_e2e.E2EStatus.OKSOMELOST
                armed = trigger(record)
                pending[0] = (pending[0] and sticky) or armed
                record.refused = 0
            else:
                record.refused += 1
        return status

    def stepped(self: odometry.Odometry, d_left: int, d_right: int) -> None:
        step(self, d_left, d_right)
        if pending[0]:
            pending[0] = False
            done[0] += 1
            edit(self)

    with pytest.MonkeyPatch.context() as monkeypatch:
        monkeypatch.setattr(fw_e2e.E2EReceiver, "check", checked)
        monkeypatch.setattr(odometry.Odometry, "step_deltas", stepped)
        yield done
