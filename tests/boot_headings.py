"""The independent check of where a rebooted firmware primed: its own HEADING is an exact function
of the counts since that frame (float64 here, cantools decoding; not ``host/judge``), so the poses
tell which frame it primed on, whatever it merged after (``tests/test_reboot_halt_delay.py``,
``tests/test_reboot_halted_first_tick.py``)."""

from __future__ import annotations

import math
from pathlib import Path

import can

from odocan.sim.contract import DBC_PATH
from odocan.sim.robot import load
from tests.dbc_typed import integers, load_can_dbc
from tests.independent_checker import HEADING_LSB_RAD

NAMED_WITHIN_S = 0.5  # a pose names a frame of its ENC_COUNTER heard this soon before it


def headings_off_lsb(robot: str, log: Path, reboot_s: float, init: bool = False
                     ) -> tuple[int, float]:
    """The new life's samples (ODOM_POSE_X after the power-up pose of the reset at ``reboot_s``)
    and their largest heading error (LSB) against the heading of the counts since the frame that
    power-up pose names. A pose names its frame by a 4-bit COUNTER: held back 30 ms, or
    integrating the halt's backlog, it may name any of its COUNTER heard in the
    ``NAMED_WITHIN_S`` before it; each is judged by the closest of those (16 frames apart, a
    wrong primed frame fits none of them).
    ``init``: a boot summary said INIT (STATE 0, UPTIME 0), no power-up pose follows: the
    firmware primed on the first encoder frame heard after that summary (its mailbox keeps the
    oldest), its samples the poses after it."""
    db = load_can_dbc(DBC_PATH)
    geometry = load(robot).firmware_params()
    per_count_rad = 2 * math.pi / (geometry["counts_per_rev"] * geometry["wheelbase_nm"])
    wrap = 1 << geometry["counter_bits"]

    def heading_rad(counts: tuple[int, int], primed: tuple[int, int]) -> float:
        d_left = (counts[0] - primed[0] + wrap // 2) % wrap - wrap // 2
        d_right = (counts[1] - primed[1] + wrap // 2) % wrap - wrap // 2
        return per_count_rad * (geometry["wheel_radius_right_nm"] * d_right
                                - geometry["wheel_radius_left_nm"] * d_left)

    encoders: list[tuple[float, int, tuple[int, int]]] = []  # (bus time, COUNTER, counts)
    primed: tuple[int, int] | None = None
    init_told = False  # (``init``) the INIT summary heard, the next frame not yet
    worst, samples = 0.0, 0
    with can.LogReader(str(log)) as reader:
        for msg in reader:
            message = db.get_message_by_frame_id(msg.arbitration_id)
            name, s = message.name, integers(message, msg.data, scaling=False)
            if name == "WHEEL_ENCODERS":
                encoders.append((msg.timestamp, s["COUNTER"], (s["LEFT_COUNT"], s["RIGHT_COUNT"])))
                if init_told:
                    primed, init_told = encoders[-1][2], False
            elif (init and name == "ODOM_STATUS" and msg.timestamp >= reboot_s and primed is None
                  and s.get("STATE", -1) == 0 and s.get("UPTIME", -1) == 0):
                init_told = True
            elif name == "ODOM_POSE_X" and msg.timestamp >= reboot_s:
                if init and primed is None:
                    continue  # the old life's, or before the frame it primed on
                named = [e[2] for e in encoders if e[1] == s["ENC_COUNTER"]
                         and msg.timestamp - e[0] <= NAMED_WITHIN_S]
                if primed is None:  # the power-up pose: (0, 0, 0) at the latest it names
                    if (s["COUNTER"], s["X"], s["HEADING"]) == (0, 0, 0):  # else: the old
                        primed = named[-1]  # life's, held back past the reset
                    continue
                offs = [(s["HEADING"] * HEADING_LSB_RAD - heading_rad(c, primed) + math.pi)
                        % (2 * math.pi) - math.pi for c in named]
                worst = max(worst, min(abs(o) for o in offs) / HEADING_LSB_RAD)
                samples += 1
    return samples, worst
