"""``BridgeConfig.hold_s`` (``host.mqtt.framehold``): each robot's frames held for its judge
change when it publishes, never what, nor the pose's batch: every publication of every robot,
its payload's bytes and the batch it went out in, the ``status`` and ``rates`` asked between
batches, set-pose commands (the judge follows them), and each robot's final status with its
verdicts, the same held as judged frame by frame, on a lockstep fleet's frames with a fault per
robot (``bench/bridge_mutated.py``: drops, silences, repeats, CRC errors, bunched and jittered
stamps, a POSE WRONG, a DISTANCE WRONG)."""

from __future__ import annotations

import importlib.util
import sys
import time
from pathlib import Path
from types import ModuleType
from typing import Any

import can
import pytest

from odocan.host.judge.reference import Geometry
from odocan.host.mqtt import topics
from odocan.host.mqtt.bridge import Bridge, BridgeConfig, RobotEndpoint
from odocan.host.mqtt.broker import BrokerURL
from odocan.host.mqtt.fleetrun import publish_phase_s
from odocan.sim import robot
from odocan.sim.fleet import robot_name

BENCH = Path(__file__).resolve().parent.parent / "bench"
ROBOTS, TICKS = 20, 400
Seen = list[tuple[int, str, bytes]]  # (batch, leaf, payload's bytes) of one robot


def _bench(name: str) -> ModuleType:
    sys.path.insert(0, str(BENCH))
    spec = importlib.util.spec_from_file_location(name, BENCH / f"{name}.py")
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def recording() -> Any:
    """A 20-robot fleet's frames over 400 ticks, robot ``i`` with ``bridge_mutated``'s fault."""
    return _bench("bridge_mutated").mutated(_bench("bridge_frames").record(ROBOTS, TICKS), 7)


def _run(recording: Any, hold_s: float) -> tuple[list[Seen], list[dict[str, Any]], int]:
    """Each robot's publications, its final status (verdicts), the frames held at most."""
    robots, batches = recording
    p = robot.load("pmir")
    with can.Bus(interface="virtual", channel="framehold") as bus:
        bridge = Bridge([RobotEndpoint(robot_name(i), bus, Geometry.of(p),
                                       counter_bits=p.counter_bits,
                                       publish_phase_s=publish_phase_s(i, 10.0))
                         for i in range(robots)],
                        config=BridgeConfig(broker=BrokerURL("127.0.0.1", 1), hold_s=hold_s,
                                            command_ack_timeout_s=1e9,  # no wall clock
                                            command_expiry_s=1e9))
        seen: list[Seen] = [[] for _ in range(robots)]
        k = 0
        for i, link in enumerate(bridge.links):
            def publish(leaf: str, payload: dict[str, Any], mine: Seen = seen[i]) -> None:
                mine.append((k, leaf, topics.dumps(payload)))
            link.publish = publish  # type: ignore[method-assign]
        most_held = 0
        for k, batch in enumerate(batches):
            for start in range(0, len(batch), 64):  # as ``_consume`` slices a batch
                bridge._handle(batch[start:start + 64])
            if bridge.hold is not None:
                most_held = max(most_held, max(len(h) for h in bridge.hold.held))
            if k % 7 == 0:  # the periodic task's turns, between batches
                bridge._publish_status(k % robots, 0.0)
                bridge._publish_rates((k + 3) % robots, k * 0.01)
            if k % 50 == 25:  # a set-pose (the judge follows it) after the frames before it
                command = b'{"id": "c%d", "x_m": 1.0, "y_m": 2.0, "heading_rad": 0.5}' % k
                answers = bridge.links[k % robots].on_command("set_pose", command)
                assert answers[0][1]["result"] == "accepted", answers
                seen[k % robots].append((k, "answer", topics.dumps(answers)))
        bridge._drain()
        bridge._end_watch()
        return seen, [r.last_status() for r in bridge.robots], most_held


def test_held_frames_publish_the_same_bytes_in_the_same_batches(
        recording: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(time, "time", lambda: 1.0)  # ``unix_s`` pinned
    judged, judged_end, _ = _run(recording, 0.0)
    held, held_end, most_held = _run(recording, 0.1)
    assert most_held > 20  # frames did wait, several ticks' (a robot sends ~4 a tick)
    for name, mine, theirs in zip(map(robot_name, range(ROBOTS)), held, judged, strict=True):
        assert [leaf for _, leaf, _ in mine].count("pose") > 20, name
        assert mine == theirs, name
    assert held_end == judged_end
    pose_wrong = [bool(s["pose_wrongs"]["episodes"]) for s in judged_end]
    distance_wrong = [not s["distance"]["passed"] for s in judged_end]
    assert any(pose_wrong)  # FAILs and PASSes among the verdicts
    assert any(distance_wrong)
    assert not all(pose_wrong)
