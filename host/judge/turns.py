"""TURNS judged with HEADING: the on-board unwrapped heading against the reference's cumulative
heading (issue #11).

ODOM_POSE_Y's TURNS (i16, wrapping) and ODOM_POSE_X's HEADING (BAM16) make the unwrapped heading
``TURNS * 2 pi + HEADING`` (dbc/odocan.dbc). The heading check compares HEADING wrapped to
(-pi, pi]; alone it cannot see a TURNS off by k (2 pi k off). Every judge (whole and streamed
``analyze``, the live judge of the monitor and the bridge) takes the heading error as the wrapped
error plus the whole turns by which the unwrapped on-board heading departs from the reference's
cumulative one, so any wrong TURNS fails the same one-LSB heading limit.

The turns are counted as the whole-turn part of (on-board unwrapped - reference cumulative -
wrapped error): an exact multiple of 2 pi up to float rounding (about 1e-11 rad at 2^15 turns),
so ``rint`` reads it without error and a correct firmware's heading error is its wrapped error
bit for bit. At a multiple of 2 pi the firmware's rounded HEADING may carry TURNS by one (ours
takes TURNS of the rounded value: ``firmware/reports.py``): TURNS k with HEADING 0 and TURNS
k - 1 with HEADING 65535 LSB are both within the tolerance of a reference within it of 2 pi k,
and both are accepted (their unwrapped heading is within the tolerance). The turn offset is read
modulo 2^16 (TURNS wraps on the wire, and the receiver cannot tell 2^16 turns apart).

A new life (reboot, set-pose, a fitted start mid-drive) takes its turns from its own start, as
the reference does (``reference_path.placed_start`` puts the fitted heading in the first
sample's turn; a power-up or set-pose start is exact), so the check follows the heading's rules.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

TURN_RAD = 2.0 * math.pi
TURNS_MODULUS = 1 << 16  # TURNS is i16 on the wire
_HALF_MODULUS = TURNS_MODULUS >> 1

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


def turn_offsets(
    onboard_unwrapped_rad: FloatArray, ref_unwrapped_rad: FloatArray, wrapped_error_rad: FloatArray
) -> IntArray:
    """Whole turns (i16-wrapped) by which the on-board unwrapped heading (TURNS * 2 pi + HEADING,
    rad) departs from the reference's cumulative heading (rad) beyond the wrapped heading error
    (rad, in (-pi, pi]): 0 for a correct firmware."""
    k = np.rint((onboard_unwrapped_rad - ref_unwrapped_rad - wrapped_error_rad) / TURN_RAD)
    turns = k.astype(np.int64)
    wrapped: IntArray = (turns + _HALF_MODULUS) % TURNS_MODULUS - _HALF_MODULUS
    return wrapped


def unwrapped_errors(
    onboard_unwrapped_rad: FloatArray, ref_unwrapped_rad: FloatArray, wrapped_error_rad: FloatArray
) -> FloatArray:
    """The heading error (rad) every judge compares with the heading tolerance: the wrapped
    error plus 2 pi per turn of ``turn_offsets`` (the wrapped error itself when TURNS is right)."""
    turns = turn_offsets(onboard_unwrapped_rad, ref_unwrapped_rad, wrapped_error_rad)
    errors: FloatArray = wrapped_error_rad + turns * TURN_RAD
    return errors


def turn_offset(onboard_unwrapped_rad: float, ref_unwrapped_rad: float,
                wrapped_error_rad: float) -> int:
    """``turn_offsets`` of one sample (the live judge: O(1), no array)."""
    k = round((onboard_unwrapped_rad - ref_unwrapped_rad - wrapped_error_rad) / TURN_RAD)
    return (k + _HALF_MODULUS) % TURNS_MODULUS - _HALF_MODULUS


def unwrapped_error(onboard_unwrapped_rad: float, ref_unwrapped_rad: float,
                    wrapped_error_rad: float) -> float:
    """``unwrapped_errors`` of one sample (rad)."""
    turns = turn_offset(onboard_unwrapped_rad, ref_unwrapped_rad, wrapped_error_rad)
    return wrapped_error_rad if turns == 0 else wrapped_error_rad + turns * TURN_RAD
