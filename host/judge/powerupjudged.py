"""The power-up pose judged against its life's start pose (issue #11: a PASS must never hide a
wrong pose), one rule for ``analyze`` (``power_up_errors``) and the live judges
(``livepowerpose``: ``names_the_prime``); a power-up's only, not a set pose's life.

A firmware primes on the first encoder frame it accepts and sends its power-up pose in that tick
(firmware/ecu.py step 5): ODOM_POSE_X and ODOM_POSE_Y of E2E COUNTER 0, naming the frame it
primed on, zero delta since it: the life's start pose exactly, (0, 0, 0). The samples leave a
pose out where the frame it names cannot be told (``samples.match_encoder``): one with a twin (a
held frame and the on-time one of one COUNTER: the firmware had either), or a pose the E2E check
refused (held back on the bus past its successors). Kobuki random 696 and 692, 8 s,
``reboot=0.5:0.3,delay=0.1:150``: the new firmware primed on a held COUNTER 1 whose on-time twin
came 10 ms later; 696's power-up pose names that twinned frame, 692's was held back 150 ms and
refused; raised 10 mm, each PASSed every judge (``tests/test_live_held_tick_start.py``).

Either candidate gives the start pose: had the firmware primed on the twin, the twin would be its
first frame, its pose zero delta there as well. So the power-up pose (the life's first ODOM_POSE_X
and ODOM_POSE_Y of COUNTER 0 whose CRC holds, whatever its E2E sequence) is judged against the
start directly when it names the prime's COUNTER and no other accepted encoder frame of that
COUNTER came after the prime before the pose was heard (``names_the_prime``: every candidate is
the prime or its twin), heard less than a pose COUNTER lap (``POSE_LAP_S``) after the prime (a
later pose of COUNTER 0 is the next lap's). Only where the life's reference starts exactly at its
first encoder frame at a power-up and no sample judged that frame already. A half whose partner
was lost is judged on what it carries (X and HEADING, or Y)."""

from __future__ import annotations

import math

import numpy as np

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.reference_path import Reference
from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M, Encoders, IntArray
from odocan.host.protocol import busfacts
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e_rows import crc_right

POSE_PERIOD_S = 0.02  # the firmware sends a pose every other encoder frame (50 Hz)
POSE_LAP_S = busfacts.ENC_COUNTER_LAP * POSE_PERIOD_S  # 320 ms: pose COUNTER 0 comes again
HALVES = ("ODOM_POSE_X", "ODOM_POSE_Y")

Start = tuple[float, float, float]  # the life's start pose: x m, y m, heading rad


def names_the_prime(enc_counter: int, prime_counter: int, since_prime: list[int]) -> bool:
    """Whether a pose naming ``enc_counter`` names the frame its life primed on (COUNTER
    ``prime_counter``) whichever candidate it is: no accepted encoder frame heard after the
    prime and before the pose (``since_prime``: their COUNTERs) has that COUNTER (a twin of the
    prime is a refused frame: the same start pose)."""
    return enc_counter == prime_counter and prime_counter not in since_prime


def start_errors(x_m: float | None, y_m: float | None, heading_rad: float | None,
                 start: Start) -> tuple[float, float]:
    """(position m, heading rad) of a power-up pose from the start pose: X and Y together as
    the distance, a half alone by the coordinate it carries (None: not carried); heading
    wrapped to (-pi, pi]."""
    dx = 0.0 if x_m is None else x_m - start[0]
    dy = 0.0 if y_m is None else y_m - start[1]
    turn = 0.0 if heading_rad is None else heading_rad - start[2]
    return math.hypot(dx, dy), abs(math.pi - (math.pi - turn) % (2 * math.pi))


def power_up_errors(frames: FrameArrays, decoder: BulkDecoder, enc: Encoders, ref: Reference,
                    judged: IntArray, set_pose: object = None) -> tuple[float, float] | None:
    """``analyze``'s power-up pose of one life (module docstring): its errors (position m,
    heading rad) from the start pose, None where it is not judged so (no exact start at the
    life's first encoder frame, its frame judged by a sample already, no such pose, or a
    set-pose's life, ``set_pose`` not None: its poses' COUNTERs do not restart there, and a
    pose held back from before the pose was set may name a frame a lap before its first)."""
    if (set_pose is not None or not ref.exact_start or ref.start != 0 or len(enc.index) == 0
            or bool(np.any(judged == 0))):
        return None
    found = [_power_up_half(frames, decoder, enc, name) for name in HALVES]
    x_row, y_row = found
    if x_row is None and y_row is None:
        return None
    turns = 0.0 if y_row is None else float(y_row["TURNS"])
    return start_errors(
        None if x_row is None else float(x_row["X"]) * POSITION_LSB_M,
        None if y_row is None else float(y_row["Y"]) * POSITION_LSB_M,
        None if x_row is None else (turns * 2 * math.pi
                                    + float(x_row["HEADING"]) * HEADING_LSB_RAD),
        (float(ref.x_m[0]), float(ref.y_m[0]), float(ref.heading_rad[0])))


def _power_up_half(frames: FrameArrays, decoder: BulkDecoder, enc: Encoders, name: str
                   ) -> dict[str, float] | None:
    """The life's first ``name`` frame of COUNTER 0 whose CRC holds (the E2E check may refuse
    it, held back past its successors), heard after the prime less than ``POSE_LAP_S`` on,
    naming the prime whichever candidate (``names_the_prime``): its raw signals."""
    try:
        rows = decoder.decode(frames, name)
    except (DecodeError, KeyError):
        return None
    index = rows["index"].astype(np.int64)
    prime_at, prime_s = int(enc.index[0]), float(enc.timestamp_s[0])
    first = np.flatnonzero((rows["COUNTER"] == 0) & (index > prime_at)
                           & (rows["timestamp_s"] - prime_s < POSE_LAP_S))
    first = first[crc_right(frames, decoder, index[first], name, unprotected=True)]
    if len(first) == 0:
        return None
    k = int(first[0])
    since = enc.counter[(enc.index > prime_at) & (enc.index < index[k])]
    if not names_the_prime(int(rows["ENC_COUNTER"][k]), int(enc.counter[0]), since.tolist()):
        return None
    return {key: float(value[k]) for key, value in rows.items() if key != "index"}


def fold_power_up(vs_ref: dict[str, float], errors: tuple[float, float] | None) -> None:
    """Put the power-up pose's ``errors`` (``power_up_errors``) into the report's
    ``onboard_vs_reference`` (no allowance at the prime: its position error is beyond none)."""
    if errors is None:
        return
    for keys, value in ((("max_position_error_m", "max_position_error_beyond_allowance_m"),
                         errors[0]), (("max_heading_error_rad",), errors[1])):
        for key in keys:
            if vs_ref.get(key) is None or value > vs_ref[key]:
                vs_ref[key] = value
