"""The telemetry's fused per-ID plans (``host.mqtt.liveplan``): each 11-bit message of the DBC
has one, made when the robot's telemetry is made, and a frame is handled by its plan alone:
with the shared route table gone after set-up, a fleet's frames (and its faults: a wrong CRC,
an E2E-valid ODOM_STATUS page the DBC does not define, a foreign identifier, an extended frame
of a DBC identifier) are judged and counted as the DBC says: every frame accepted or refused
once, by its message's name, a foreign one by its hex identifier.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

import can

from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.bridge import Bridge, BridgeConfig, RobotEndpoint
from odocan.host.mqtt.broker import BrokerURL
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.host.protocol.e2e import e2e_messages
from odocan.host.protocol.e2e_crc import crc8h2f_p02_one
from odocan.host.protocol.e2e_live import E2EMonitor
from odocan.sim import robot
from odocan.sim.contract import database
from odocan.sim.fleet import Fleet, FleetConfig

Frame = tuple[float, int, bytes, bool]


class _Gone(dict[int, Any]):
    """A route table that may not be read any more."""

    def get(self, *_args: Any) -> Any:
        raise AssertionError("a frame read the route table")

    def __getitem__(self, _key: int) -> Any:
        raise AssertionError("a frame read the route table")


def _fleet_frames(ticks: int) -> list[Frame]:
    """Robot 0's frames of a lockstep fleet of one, as the bridge is given them."""
    fleet = Fleet(FleetConfig(robots=1, robot=robot.load("pmir")))
    frames: list[Frame] = []
    try:
        for k in range(ticks):
            fleet.step(k)
            for _, f in fleet.take_batch():
                if isinstance(f, can.Message):
                    frames.append((f.timestamp, f.arbitration_id, bytes(f.data), False))
                else:
                    t_s, can_id, data = f
                    frames.append((t_s, can_id, bytes(data), False))
    finally:
        fleet.close()
    return frames


def _undefined_page(data: bytes) -> bytes:
    """An ODOM_STATUS payload of the same COUNTER on a PAGE the DBC does not define, its CRC
    made right (E2E-valid, undecodable)."""
    db = database()
    message = db.get_message_by_name("ODOM_STATUS")
    page = message.get_signal_by_name("PAGE")
    undefined = next(v for v in range(1 << page.length) if v not in (page.choices or {}))
    mask = ((1 << page.length) - 1) << page.start
    word = int.from_bytes(data, "little") & ~mask | undefined << page.start
    raw = bytearray(word.to_bytes(8, "little"))
    data_ids = e2e_messages(db)[message.frame_id].data_ids
    assert data_ids is not None
    raw[0] = crc8h2f_p02_one(bytes(raw), data_ids[raw[1] & 0x0F])
    return bytes(raw)


def _faulted(frames: list[Frame]) -> tuple[list[Frame], Counter[str]]:
    """``frames`` with four faults put in; the refusals they must cause, by key."""
    db = database()
    encoders = db.get_message_by_name("WHEEL_ENCODERS").frame_id
    status = db.get_message_by_name("ODOM_STATUS").frame_id
    out, expected = list(frames), Counter[str]()
    k = next(i for i, f in enumerate(out) if f[1] == encoders and i > len(out) // 2)
    t_s, can_id, data, _ = out[k]
    out[k] = (t_s, can_id, bytes([data[0] ^ 0xFF]) + data[1:], False)  # a wrong CRC
    expected["WHEEL_ENCODERS"] += 1
    k = next(i for i, f in enumerate(out) if f[1] == status and i > len(out) // 3)
    t_s, can_id, data, _ = out[k]
    out[k] = (t_s, can_id, _undefined_page(data), False)
    expected["ODOM_STATUS"] += 1
    t_s = out[len(out) // 4][0]
    out.insert(len(out) // 4, (t_s, 0x7FF, bytes(8), False))  # no message of the DBC
    expected["0x7ff"] += 1
    out.insert(len(out) // 4, (t_s, encoders, bytes(8), True))  # a DBC id, extended
    expected["WHEEL_ENCODERS"] += 1  # (refused: no 11-bit route; counted by the id's name)
    return out, expected


def test_a_frame_is_handled_by_its_plan_alone() -> None:
    db = database()
    p = robot.load("pmir")
    telemetry = RobotTelemetry("robot0", Geometry.of(p), "exact", counter_bits=p.counter_bits)
    assert set(telemetry.plans) == {m.frame_id for m in db.messages if not m.is_extended_frame}
    telemetry._routes = _Gone()
    frames, expected = _faulted(_fleet_frames(300))
    published = Counter[str]()
    for t_s, can_id, data, extended in frames:
        for leaf, _ in telemetry.feed_fields(t_s, can_id, data, extended):
            published[leaf] += 1
    assert dict(telemetry.rejected) == dict(expected)
    names = {m.frame_id: m.name for m in db.messages}
    heard = Counter(names.get(f[1], "") for f in frames if not f[3] and f[1] in names)
    assert sum(telemetry.frames.values()) + 2 == sum(heard.values())  # all but the two faults
    assert telemetry.frames["WHEEL_ENCODERS"] == heard["WHEEL_ENCODERS"] - 1
    assert published["pose"] > 20
    assert published["error"] >= published["pose"] - 1
    assert telemetry.tracker.wrongs.as_dict()["episodes"] == 0  # a correct firmware: PASS


def test_the_bridge_gives_a_frame_of_the_dbc_to_its_plan() -> None:
    """``Bridge._handle``: a fleet's frame of a DBC message straight to its plan, no
    ``feed_fields`` call around it; a foreign identifier through ``feed_fields``."""
    p = robot.load("pmir")
    frames = _fleet_frames(60)
    frames.insert(len(frames) // 2, (frames[len(frames) // 2][0], 0x7FF, bytes(8), False))
    with can.Bus(interface="virtual", channel="liveplan-bridge") as bus:
        bridge = Bridge([RobotEndpoint("robot001", bus, Geometry.of(p),
                                       counter_bits=p.counter_bits)],
                        config=BridgeConfig(broker=BrokerURL(host="127.0.0.1", port=1)))
        published: list[str] = []
        bridge.links[0].publish = (  # type: ignore[method-assign]
            lambda leaf, payload: published.append(leaf))
        robot_ = bridge.robots[0]
        through_feed: list[int] = []
        feed_fields = robot_.feed_fields

        def counted(t_s: float, can_id: int, data: bytes, extended: bool) -> list[Any]:
            through_feed.append(can_id)
            return feed_fields(t_s, can_id, data, extended)

        robot_.feed_fields = counted
        bridge._handle([(0, (t_s, can_id, data)) for t_s, can_id, data, _ in frames])
    assert through_feed == [0x7FF]
    assert bridge.frames_failed == 0
    assert robot_.telemetry.rejected == {"0x7ff": 1}
    assert published.count("pose") >= 5


def test_the_e2e_check_takes_its_frame_by_position() -> None:
    """The plans call ``E2EMonitor.check`` by position (CPython's keyword call is slower): the
    same statuses and counts as by keyword, frame by frame, a wrong CRC among them."""
    frames, _ = _faulted(_fleet_frames(40))
    by_position, by_keyword = E2EMonitor(), E2EMonitor()
    for t_s, can_id, data, extended in frames:
        assert (by_position.check(can_id, data, extended, t_s)
                == by_keyword.check(can_id, data, extended=extended, timestamp_s=t_s))
    assert by_position.counts() == by_keyword.counts()
    assert by_position.counts()["WHEEL_ENCODERS"]["crc_errors"] == 1
