"""The bridge's payloads carry the firmware's values exactly, without float noise.

A lockstep run's frames are decoded here with cantools to their raw integers; every ``pose`` and
``truth`` publication must give them back (``round(value / scale)``), each value being the
correctly rounded decimal of the raw one (``raw / 10**4``, not cantools' ``raw * 0.0001``:
``-0.0009000000000000001``), and ``status`` must give the PROFILE page's CRC in one form."""

from __future__ import annotations

import math
from typing import Any

import can

from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim import robot
from odocan.sim.contract import database
from odocan.sim.rig import LockstepRig, RigConfig
from tests.dbc_typed import numbers

DB = database()
PMIR = robot.load("pmir")
HEADING_LSB = DB.get_message_by_name("ODOM_POSE_X").get_signal_by_name("HEADING").scale


def run() -> tuple[list[tuple[str, dict[str, Any]]], dict[tuple[str, int, int], dict[str, int]],
                   RobotTelemetry]:
    telemetry = RobotTelemetry("r", Geometry.of(PMIR), "exact", counter_bits=PMIR.counter_bits,
                               publish_hz=20)
    out: list[tuple[str, dict[str, Any]]] = []
    raw: dict[tuple[str, int, int], dict[str, int]] = {}  # (message, PART, ENC_COUNTER)

    class Feed(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            message = DB.get_message_by_frame_id(msg.arbitration_id)
            if message.name in ("ODOM_POSE_X", "ODOM_POSE_Y", "SIM_TRUTH"):
                s = numbers(DB, message.name, bytes(msg.data), scaling=False)  # cantools
                raw[(message.name, int(s.get("PART", 0)), int(s["ENC_COUNTER"]))] = {
                    k: int(v) for k, v in s.items()}  # (ENC_COUNTER wraps: the latest)
            for leaf, payload in telemetry.feed(msg):  # the frames it came from, as they were
                out.append((leaf, {**payload, "raw": dict(raw)}))

    with LockstepRig(RigConfig(robot=PMIR, seed=3, channel="test-mqtt-lsb"), [Feed()]) as rig:
        rig.run(3.0)
    return out, raw, telemetry


def heading_raw(heading_rad: float) -> int:
    return round((heading_rad % math.tau) / HEADING_LSB) % 65536


def test_pose_and_truth_values_are_their_raw_integers_exactly() -> None:
    out, _, _ = run()
    poses = [p for leaf, p in out if leaf == "pose"]
    truths = [p for leaf, p in out if leaf == "truth"]
    assert len(poses) >= 50
    assert len(truths) >= 20
    for p in poses:
        raw = p["raw"]
        x, y = raw[("ODOM_POSE_X", 0, p["enc_counter"])], raw[("ODOM_POSE_Y", 0, p["enc_counter"])]
        assert p["x_m"] == x["X"] / 10**4
        assert p["y_m"] == y["Y"] / 10**4
        assert heading_raw(p["heading_rad"]) == x["HEADING"]
        assert heading_raw(p["heading_unwrapped_rad"]) == x["HEADING"]
        turns = (p["heading_unwrapped_rad"] + HEADING_LSB / 2) // math.tau  # TURNS 2 pi + HEADING
        assert turns == y["TURNS"]
        for key in ("linear_vel_m_s", "angular_vel_rad_s", "distance_m"):
            assert p[key] == round(p[key] * 10**3) / 10**3  # an LSB of 0.001
    for t in truths:
        raw = t["raw"]
        enc = t["enc_counter"]
        assert t["x_m"] == raw[("SIM_TRUTH", 0, enc)]["X"] / 10**4
        assert t["y_m"] == raw[("SIM_TRUTH", 1, enc)]["Y"] / 10**4
        assert heading_raw(t["heading_rad"]) == raw[("SIM_TRUTH", 2, enc)]["HEADING"]


def test_the_profile_crc_has_one_form_in_status() -> None:
    _, _, telemetry = run()
    status = telemetry.status()[1]
    crc = status["firmware"]["profile"]["profile_crc"]
    assert crc == status["profile"]["profile_crc"]
    assert isinstance(crc, str)
    assert crc.startswith("0x")
    assert len(crc) == 10
