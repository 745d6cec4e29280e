"""The bridge's parts without a broker: command validation, telemetry, broker URLs, the fleet."""

from __future__ import annotations

import itertools
from collections.abc import Callable
from typing import Any

import can
import cantools
import pytest

from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.broker import BrokerURL
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.host.protocol.commands import CommandEncoder, CommandRejected
from odocan.host.protocol.e2e_live import E2EMonitor
from odocan.sim import robot
from odocan.sim.contract import DBC_PATH, database
from odocan.sim.fleet import Fleet, FleetConfig, frame_fields
from odocan.sim.rig import LockstepRig, RigConfig
from tests.dbc_typed import numbers

PMIR = robot.load("pmir")
GEOMETRY = Geometry.of(PMIR)


def test_set_pose_frames_pass_the_e2e_check_and_carry_the_values() -> None:
    command = CommandEncoder().encode(
        "set_pose", b'{"id": 7, "x_m": -1.25, "y_m": 3.5, "heading_rad": 6.5}')
    monitor = E2EMonitor()
    message = database().get_message_by_name("ODOM_SET_POSE")
    decoded = []
    for frame in command.frames:
        assert monitor.check(frame.can_id, frame.data) == "ok"
        decoded.append(numbers(database(), message.frame_id, frame.data))
    assert [d["FIELD"] for d in decoded] == [0, 1, 2, 15]
    assert decoded[0]["X"] == pytest.approx(-1.25)
    assert decoded[1]["Y"] == pytest.approx(3.5)
    assert decoded[2]["HEADING"] == pytest.approx(6.5 - 2 * 3.141592653589793, abs=1e-4)
    assert [f.final for f in command.frames] == [False, False, False, True]
    assert command.cmd_id == 7


def test_nav_goal_is_unsupported_by_a_dbc_without_nav_goal() -> None:
    db = cantools.database.load_file(DBC_PATH, strict=True)
    assert isinstance(db, cantools.database.can.Database)
    db.messages[:] = [m for m in db.messages if m.name != "NAV_GOAL"]
    db.refresh()
    with pytest.raises(CommandRejected, match="unsupported by this DBC") as info:
        CommandEncoder(db).encode("nav_goal", b'{"id": "g", "x_m": 1, "y_m": 2}')
    assert info.value.cmd_id == "g"


def test_nav_goal_frames() -> None:
    command = CommandEncoder().encode("nav_goal", b'{"x_m": 1, "y_m": 2, "goal_id": 9}')
    message = database().get_message_by_name("NAV_GOAL")
    go = numbers(database(), message.frame_id, command.frames[-1].data)
    assert len(command.frames) == 3  # X, Y, GO: no HEADING frame without heading_rad
    assert (go["GOAL_ID"], go["NO_FINAL_HEADING"], go["APPEND"]) == (9, 1, 0)


@pytest.mark.parametrize(("payload", "reason"), [
    (b'{"x_m": 1, "y_m": 2, "heading_rad": 0, "id": true}', "id must be"),
    (b'{"x_m": 1e300, "y_m": 2, "heading_rad": 0}', "out of range"),
    (b'{"x_m": 1, "y_m": -214748.5, "heading_rad": 0}', "y_m=-214748.5 out of range"),
    (b'{"x_m": 1, "y_m": 2, "heading_rad": Infinity}', "heading_rad must be finite"),
    (b'{"x_m": 1, "y_m": 2, "heading_rad": 0}' + b" " * 5000, "payload too large"),
    (b"\xff\xfe", "malformed JSON"),
])
def test_set_pose_rejections(payload: bytes, reason: str) -> None:
    with pytest.raises(CommandRejected, match=reason):
        CommandEncoder().encode("set_pose", payload)


def test_a_rejected_command_does_not_use_an_e2e_counter() -> None:
    encoder = CommandEncoder()
    with pytest.raises(CommandRejected):
        encoder.encode("set_pose", b'{"x_m": 1, "y_m": 2, "heading_rad": "north"}')
    command = encoder.encode("set_pose", b'{"x_m": 1, "y_m": 2, "heading_rad": 0}')
    assert [f.counter for f in command.frames] == [0, 1, 2, 3]


@pytest.mark.parametrize(("url", "expected"), [
    ("mqtt://127.0.0.1", ("127.0.0.1", 1883, False, None, None)),
    ("mqtt://u:p%40ss@127.0.0.1:1884", ("127.0.0.1", 1884, False, "u", "p@ss")),
    ("mqtts://127.0.0.1", ("127.0.0.1", 8883, True, None, None)),
])
def test_broker_urls(url: str, expected: tuple[object, ...]) -> None:
    b = BrokerURL.parse(url)
    assert (b.host, b.port, b.tls, b.username, b.password) == expected
    assert "p%40ss" not in str(b)
    assert "p@ss" not in str(b)


@pytest.mark.parametrize("url", ["http://x", "mqtt://", "mqtt://h:99999", "mqtt://h/topic"])
def test_bad_broker_urls(url: str) -> None:
    with pytest.raises(ValueError, match="--broker"):
        BrokerURL.parse(url)


def test_tls_files_need_mqtts(tmp_path: object) -> None:
    with pytest.raises(ValueError, match="mqtts"):
        BrokerURL.parse("mqtt://h", ca=__file__)  # type: ignore[arg-type]


def test_telemetry_of_a_lockstep_run_matches_the_reference() -> None:
    """5 Hz of pose for 5 s, with its reference and error once the first life is judged.

    Since the restart merge the first life's samples wait for the power-up's ENC_E2E_OK page
    (~0.1 s) to be judged from (0, 0, 0), as analyze judges them: the pose of 1 ms is published
    at once, alone (no reference is known yet); the samples judged at the page fall in that
    same publication period, so the first error is the next period's (0.201 s) and the errors
    count 5 Hz from there: 24 in 5 s, each within the bus LSB."""
    telemetry = RobotTelemetry("r", GEOMETRY, "exact", counter_bits=PMIR.counter_bits,
                               publish_hz=5)
    out = []

    class Feed(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            out.extend(telemetry.feed(msg))

    with LockstepRig(RigConfig(robot=PMIR, seed=5, channel="test-mqtt-telemetry"),
                     [Feed()]) as rig:
        rig.run(5.0)
    errors = [p for leaf, p in out if leaf == "error"]
    assert len(errors) == 24  # 5 Hz from the first period after the page
    assert errors[0]["t_s"] == pytest.approx(0.201)
    assert max(e["pose_vs_reference"]["dpos_m"] for e in errors) < 2e-4  # 0.1 mm LSB on the bus
    assert "reference_vs_truth" in errors[-1]
    truths = [p for leaf, p in out if leaf == "truth"]
    assert len(truths) == 25  # SIM_TRUTH every 100 ms, published with the pose at 5 Hz
    poses = {p["t_s"] for leaf, p in out if leaf == "pose"}
    assert all(p["unix_s"] and p["t_s"] <= max(poses) for p in truths)
    leaves = [leaf for leaf, _ in out]
    assert leaves[:2] == ["truth", "pose"]  # before the first pose: alone; that pose unjudged
    assert leaves[2:] == ["pose", "reference", "error", "truth"] * 24  # then with the pose
    assert telemetry.rejected == {}
    hz = telemetry.rates(5.0)[1]["hz"]
    assert hz["WHEEL_ENCODERS"] == pytest.approx(100.0)  # 500 frames over the 5 s "window"


def test_without_poses_the_truth_goes_alone_at_the_publish_rate() -> None:
    """The truth rides with the pose; while no pose is published (the firmware silent, its pose
    frames lost) it still goes out, alone, at most ``publish_hz`` times a second."""
    telemetry = RobotTelemetry("r", GEOMETRY, "exact", counter_bits=PMIR.counter_bits,
                               publish_hz=5)
    pose_ids = {telemetry.db.get_message_by_name(n).frame_id for n in ("ODOM_POSE_X",
                                                                         "ODOM_POSE_Y")}
    out = []

    class Feed(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            if msg.arbitration_id not in pose_ids:
                out.extend(telemetry.feed(msg))

    with LockstepRig(RigConfig(robot=PMIR, seed=5, channel="test-mqtt-truth-alone"),
                     [Feed()]) as rig:
        rig.run(5.0)
    assert {leaf for leaf, _ in out} == {"truth"}
    stamps = [p["t_s"] for _, p in out]
    assert len(stamps) == 25  # SIM_TRUTH every 100 ms, published every 200 ms
    assert min(b - a for a, b in itertools.pairwise(stamps)) == pytest.approx(0.2)


def test_telemetry_takes_the_fleets_frame_tuples_as_it_takes_messages() -> None:
    """``feed_frame`` of the transport's ``(t, id, payload)`` tuples (the fleet's path, no
    ``Message`` built) publishes what ``feed`` publishes for the same frames as Messages."""
    with Fleet(FleetConfig(robots=1, robot=PMIR, seed=8)) as fleet:
        frames = []
        for k in range(300):
            fleet.step(k)
            frames += [f for _, f in fleet.take_batch()]
    assert all(type(f) is tuple for f in frames)  # the lean path really carried them
    by_tuple, by_message = (RobotTelemetry("r", GEOMETRY, "exact", counter_bits=PMIR.counter_bits)
                            for _ in range(2))
    out_tuple, out_message = [], []
    for frame in frames:
        t_s, can_id, data = frame_fields(frame)
        out_tuple += by_tuple.feed_frame(frame)
        out_message += by_message.feed(
            can.Message(timestamp=t_s, arbitration_id=can_id, is_extended_id=False, data=data))

    def unstamped(out: list[tuple[str, dict[str, object]]]) -> list[tuple[str, object]]:
        return [(leaf, {k: v for k, v in p.items() if k != "unix_s"}) for leaf, p in out]

    assert len([leaf for leaf, _ in out_tuple if leaf == "error"]) >= 25  # 10 Hz for 3 s
    assert unstamped(out_tuple) == unstamped(out_message)
    assert by_tuple.frames == by_message.frames
    assert not by_tuple.rejected


@pytest.mark.parametrize(("index", "start_tick", "truth_phase"), [(1, 1, 0), (2, 0, 2)])
def test_a_fleet_robot_sends_the_lockstep_rigs_frames(
    index: int, start_tick: int, truth_phase: int
) -> None:
    """Robot i of a fleet is the lockstep rig with seed seed + i, byte for byte: odd robots start
    one fleet tick late and pairs of robots take turns for SIM_TRUTH (spreading the load)."""
    with Fleet(FleetConfig(robots=3, robot=PMIR, seed=10)) as fleet:
        fleet_frames: list[bytes] = []
        for k in range(120 + start_tick):
            fleet.step(k)
            fleet_frames += [frame_fields(f)[2] for i, f in fleet.take_batch() if i == index]
    rig_frames: list[bytes] = []

    class Keep(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            rig_frames.append(bytes(msg.data))

    config = RigConfig(robot=PMIR, seed=10 + index, channel="test-mqtt-fleet-rig",
                       truth_phase_ticks=truth_phase)
    with LockstepRig(config, [Keep()]) as rig:
        rig.run(1.2)
    assert fleet_frames == rig_frames
    assert any(frame for frame in rig_frames)


def test_fleet_view_folds_messages_into_a_table() -> None:
    from odocan.host.mqtt.fleetview import RobotState, apply

    table: dict[str, RobotState] = {}
    assert apply(table, "odocan/robot002/status", b'{"state": "online", "seq": 1}')
    assert apply(table, "odocan/robot002/pose", b'{"x_m": 1.5}')
    assert not apply(table, "odocan/robot002/pose", b"not json")
    assert not apply(table, "elsewhere/robot002/pose", b"{}")
    assert table["robot002"].online
    assert table["robot002"].pose == {"x_m": 1.5}


def test_a_telemetry_sender_cancelled_as_its_write_completes_stops() -> None:
    """The session ends (cancel) in the same turn paho reports the socket write: the sender must
    end, not swallow the cancellation and wait forever for more telemetry (asyncio.wait_for in
    Python 3.11 does swallow it: the fleet's stop then hung)."""
    import asyncio

    import paho.mqtt.client as paho

    from odocan.host.mqtt.client import LinkClient

    async def scenario() -> bool:
        client = LinkClient(hostname="127.0.0.1", on_refused=lambda *_: None,
                         on_overflow=lambda _: None, max_waiting=1, timeout=5.0)
        info = paho.MQTTMessageInfo(7)  # queued, not yet written
        waiter = asyncio.create_task(client.written(info))
        await asyncio.sleep(0)
        client._on_publish(client._client, None, 7, 0, None)  # the write completes ...
        waiter.cancel()  # ... as the session's task group cancels the sender
        try:
            await waiter
        except asyncio.CancelledError:
            return True
        return False

    assert asyncio.run(scenario())


def test_the_periodic_publications_of_a_fleet_are_spread_over_the_period() -> None:
    """``status`` and ``rates`` of 20 robots on a simulated clock: online at once, then every
    robot's once a period in a loop turn of its own (no burst of the whole fleet); after the
    loop stalls 2.3 s (four periods), each robot's once to catch up and the spread kept (before:
    every robot on one turn for good). A simulated clock, since a loaded machine's real stall
    is exactly what this checks (the wall-clock version failed on a stalled CI machine)."""
    import asyncio

    from odocan.host.mqtt.bridge import Bridge, BridgeConfig, RobotEndpoint

    period_s, turn_s, stall_s, end_s = 0.5, 0.5 / 20, 2.3, 5.0
    clock_s = [0.0]

    class Done(Exception):
        pass

    async def sleep(seconds: float) -> None:
        clock_s[0] += seconds + (stall_s if abs(clock_s[0] - 1.0) < turn_s / 2 else 0.0)
        if clock_s[0] > end_s:
            raise Done

    with can.Bus(interface="virtual", channel="test-mqtt-periodic") as bus:
        bridge = Bridge([RobotEndpoint(f"robot{i:03d}", bus, GEOMETRY,
                                       counter_bits=PMIR.counter_bits) for i in range(20)],
                        config=BridgeConfig(broker=BrokerURL.parse("mqtt://127.0.0.1"),
                                            status_period_s=period_s, rates_period_s=period_s))
        sent: list[tuple[float, int, str]] = []

        def recorder(robot: int) -> Callable[[str, dict[str, Any]], None]:
            return lambda leaf, _payload: sent.append((clock_s[0], robot, leaf))

        for index, robot in enumerate(bridge.robots):
            robot.link.publish = recorder(index)  # type: ignore[method-assign,assignment]
        with pytest.raises(Done):
            asyncio.run(bridge._periodic(clock=lambda: clock_s[0], sleep=sleep))

    def window(first_s: float, last_s: float) -> list[tuple[float, int, str]]:
        """The publications of the turns after ``first_s`` up to ``last_s``'s (half a turn
        either side: the clock's sums are a hair off the turns)."""
        return [(t, robot, leaf) for t, robot, leaf in sent
                if first_s + turn_s / 2 < t <= last_s + turn_s / 2]

    assert sorted((t, robot, leaf) for t, robot, leaf in sent if t == 0.0) == [
        (0.0, robot, "status") for robot in range(20)]  # online at once
    stalled_s = 1.0 + turn_s + stall_s
    periods = [(0.0, period_s), (period_s, 2 * period_s),  # before the stall
               (stalled_s, stalled_s + period_s), (stalled_s + period_s, stalled_s + 2 * period_s)]
    for first_s, last_s in periods:
        published = window(first_s, last_s)
        for leaf in ("status", "rates"):  # every robot's once a period
            assert sorted(robot for _, robot, lf in published if lf == leaf) == list(range(20))
        turns = {t: {robot for t2, robot, _ in published if t2 == t} for t, _, _ in published}
        assert sorted(map(len, turns.values())) == [1] * 20, turns  # a robot a turn, 20 turns
    caught_up = window(1.0, stalled_s)  # the stall's end: each robot's once, not four times
    assert len({t for t, _, _ in caught_up}) == 1  # in one turn
    for leaf in ("status", "rates"):
        assert sorted(robot for _, robot, lf in caught_up if lf == leaf) == list(range(20))
    for t, slot, _ in window(stalled_s, end_s):  # each robot on its own phase, as before
        assert round((t / turn_s - slot - 1) % 20, 6) in (0.0, 20.0), (t, slot)


def test_a_fleets_publications_are_spread_over_the_ticks_of_a_period() -> None:
    """With ``fleetrun.publish_phase_s`` the robots of a fleet publish their poses on different
    ticks of the 100 ms period (without: every even robot on one tick, every odd on the next),
    each still at 10 Hz; the phase only delays the first publication."""
    from odocan.host.mqtt.fleetrun import publish_phase_s

    def pose_ticks(phased: bool) -> dict[int, list[int]]:
        ticks: dict[int, list[int]] = {}
        with Fleet(FleetConfig(robots=10, robot=PMIR, seed=4)) as fleet:
            telemetry = [RobotTelemetry(name, GEOMETRY, "exact", counter_bits=PMIR.counter_bits,
                                        publish_phase_s=publish_phase_s(i, 10.0) if phased
                                        else 0.0)
                         for i, name in enumerate(fleet.names)]
            for k in range(300):
                fleet.step(k)
                for i, frame in fleet.take_batch():
                    if any(leaf == "pose" for leaf, _ in telemetry[i].feed_frame(frame)):
                        ticks.setdefault(i, []).append(k)
        return ticks

    plain, phased = pose_ticks(False), pose_ticks(True)
    assert len({k % 10 for ks in plain.values() for k in ks}) == 2
    assert len({k % 10 for ks in phased.values() for k in ks}) == 10
    for i, ks in phased.items():
        assert all(b - a == 10 for a, b in itertools.pairwise(ks))  # 10 Hz
        assert ks[0] - plain[i][0] == 2 * (i // 2 % 5)  # delayed by its phase only
        assert len(ks) >= len(plain[i]) - 1
