"""`odocan fleet` on a late machine: every robot sends one encoder frame per release, skipped too.

The fleet's real-time loop (``sim.fleet.run_realtime``) skips the releases it fell a whole period
behind on. Stepped straight to the release it got to, a robot put several periods of motion under
one COUNTER step, which its firmware rightly refused as faster than the robot can go (kobuki's
0.7 m/s bound), and the run was UNJUDGED or FAILed a correct firmware. As ``odocan sim`` does
(tests/test_sim_late_ticks.py), each skipped release's sample is sent late, taken at its own
release. The reference is independent of the real-time path: the same fleet stepped without a skip.
"""

from __future__ import annotations

import asyncio
import itertools
import math

import pytest

from odocan.firmware import frames as fr
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.fleetjudge import judge_robot
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim import fleet as sim_fleet
from odocan.sim import robot
from odocan.sim.board import TICK_S
from odocan.sim.fleet import Batch, Fleet, FleetConfig, frame_fields

SEED = 7
DURATION_S = 3.0
# The tick run for release k starts this late (s): 4 ms (inside the period), 25 ms (two releases
# skipped), 13 ms (one), 31 ms (three); every other tick on time.
LATENESS_S = {5: 0.004, 40: 0.025, 90: 0.013, 150: 0.0095, 220: 0.031}


class LateClock:
    """A fake ``RealTimeClock`` for ``run_realtime``, which reads it twice a tick: before its
    sleep (answered far ahead: no sleep) and for the tick's lateness (its release plus
    ``LATENESS_S``). It follows the loop's releases as the loop does (a whole period late skips)."""

    def __init__(self) -> None:
        self.reads = 0
        self.k = 0

    def now_s(self) -> float:
        self.reads += 1
        if self.reads % 2:
            return 1e9
        late_s = LATENESS_S.get(self.k, 0.0)
        now_s = self.k * TICK_S + late_s
        self.k += int(late_s / TICK_S) + 1
        return now_s


def _encoders(batches: list[Batch], robots: int) -> list[list[bytes]]:
    out: list[list[bytes]] = [[] for _ in range(robots)]
    for batch in batches:
        for i, frame in batch:
            _, can_id, data = frame_fields(frame)
            if can_id == fr.WHEEL_ENCODERS_ID:
                out[i].append(data)
    return out


def test_a_late_fleet_sends_one_encoder_frame_per_release_and_judges_its_robots(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    profile = robot.load("kobuki")
    config = FleetConfig(robots=2, robot=profile, seed=SEED)
    monkeypatch.setattr(sim_fleet, "RealTimeClock", LateClock)
    batches: list[Batch] = []
    with Fleet(config) as fleet:
        telemetry = [RobotTelemetry(name, Geometry.of(profile), "exact",
                                    counter_bits=profile.counter_bits) for name in fleet.names]

        def on_batch(batch: Batch) -> None:
            batches.append(batch)
            for i, frame in batch:
                telemetry[i].feed_frame(frame)

        stats = asyncio.run(sim_fleet.run_realtime(fleet, duration_s=DURATION_S,
                                                   on_batch=on_batch))
    releases = round(DURATION_S / TICK_S)
    assert stats.skipped_releases == 2 + 1 + 3  # the premise: the loop did skip releases
    assert stats.ticks + stats.skipped_releases == releases
    with Fleet(config) as reference_fleet:
        reference: list[Batch] = []
        for k in range(releases):
            reference_fleet.step(k)
            reference.append(reference_fleet.take_batch())
    per_period = math.ceil(0.7 * TICK_S / (2 * math.pi * 0.035 / 2578)) + 1  # kobuki's bound
    for index, (heard, lockstep) in enumerate(zip(_encoders(batches, 2),
                                                  _encoders(reference, 2), strict=True)):
        # One encoder frame per release of the robot (odd robots start a tick late), the
        # skipped ones' sent late: COUNTER +1 each, as the DBC says.
        assert len(heard) == releases - index
        assert all((b[1] - a[1]) & 0xF == 1 for a, b in itertools.pairwise(heard))
        # The skipped releases' driver commands go out too (open loop, a function of time):
        # the robot moves as without the skips, the lockstep frames byte for byte.
        assert heard == lockstep
        # (So each wheel's step stays within one period's motion at kobuki's 0.7 m/s.)
        for k, (a, b) in enumerate(itertools.pairwise(heard), start=1):
            for lo in (2, 5):  # LEFT_COUNT, RIGHT_COUNT (u24, 16-bit counters)
                step = (int.from_bytes(b[lo:lo + 3], "little")
                        - int.from_bytes(a[lo:lo + 3], "little"))
                step = (step + 0x8000) % 0x10000 - 0x8000
                assert abs(step) <= per_period, f"robot {index} release {k}: {step} counts"
    for t in telemetry:
        tracker = t.tracker
        verdict = judge_robot(tracker.vs_reference, tracker.vs_truth,
                              beyond_allowance_m=tracker.max_beyond_allowance_m)
        assert verdict["verdict"] == "PASS", verdict["reason"]
