"""The firmware tells a second sender on ODOM_CONFIG (issue #11: two sources on one ID).

Two tools, each with its own E2E COUNTER sequence, both start at COUNTER 0: the firmware's
Profile 2 receiver accepts the first frame of COUNTER 0 and refuses the second (E2E REPEATED).
On main it dropped it unanswered, so the second tool learnt nothing (and took the first's
ODOM_ACK for its own). Now a REPEATED frame with other content than the last one accepted is
answered NACK REPEATED (the DBC's VAL_ 11): dropped, nothing staged; an exact duplicate of the
accepted frame (CAN's double reception) stays unanswered, as it was answered once. The Python
firmware and the C port answer bit for bit the same (decoded here with cantools).
"""

from __future__ import annotations

from typing import Any, cast

import pytest

from odocan.firmware import frames as fr
from odocan.firmware.ecu import OdomEcu
from odocan.host.protocol.commands import CommandEncoder
from odocan.sim import cboard
from odocan.sim.contract import database
from odocan.sim.rig import firmware_params
from odocan.sim.robot import load

KOBUKI = load("kobuki")
CONFIG = {"counts_per_rev": KOBUKI.counts_per_rev, "wheel_radius_left_m": 0.035,
          "wheel_radius_right_m": 0.035, "wheelbase_m": 0.25, "counter_bits": 16,
          "integrator": "exact"}


class _Hal:
    def __init__(self) -> None:
        self.sent: list[tuple[int, bytes]] = []

    def transmit(self, can_id: int, data: bytes) -> bool:
        self.sent.append((can_id, bytes(data)))
        return True


def _answers(kind: str, frames: list[bytes]) -> tuple[list[bytes], list[dict[str, Any]]]:
    """``frames`` (ODOM_CONFIG) into a fresh firmware of ``kind``, one tick: its ODOM_ACKs,
    raw and decoded (cantools, choices by name)."""
    hal = _Hal()
    params = firmware_params(KOBUKI, "exact")
    ecu: Any = OdomEcu(hal, params) if kind == "python" else cboard.CEcu(hal, params)
    for data in frames:
        ecu.isr_can_rx(fr.ODOM_CONFIG_ID, data)
    ecu.tick()
    raw = [data for can_id, data in hal.sent if can_id == fr.ODOM_ACK_ID]
    db = database()
    return raw, [cast(dict[str, Any], db.decode_message(fr.ODOM_ACK_ID, d)) for d in raw]


def _first_frames() -> tuple[bytes, bytes, bytes]:
    """COUNTER 0 of two tools (COUNTS_PER_REV 2578 and 1000), and the first's COUNTER 1."""
    mine = CommandEncoder().build("config", CONFIG).frames
    other = CommandEncoder().build("config", {**CONFIG, "counts_per_rev": 1000}).frames
    return mine[0].data, other[0].data, mine[1].data


@pytest.mark.parametrize("kind", ["python", "c"])
def test_a_second_sender_s_frame_of_the_same_counter_is_nacked_repeated(kind: str) -> None:
    first, second, then = _first_frames()
    _, acks = _answers(kind, [first, first, second, then])
    assert [(a["REQUEST_COUNTER"], a["REQUEST_FIELD"], a["RESULT"], a["REASON"])
            for a in acks] == [
        (0, 0, "ACK", "OK"),  # the first tool's COUNTER 0; its duplicate: no answer
        (0, 0, "NACK", "REPEATED"),  # the second tool's: told, nothing staged
        (1, 1, "ACK", "OK"),  # the first tool goes on
    ]


def test_the_c_port_answers_bit_for_bit_as_the_python_firmware() -> None:
    first, second, then = _first_frames()
    frames = [first, second, second, first, then, then, second]
    assert _answers("c", frames)[0] == _answers("python", frames)[0]
