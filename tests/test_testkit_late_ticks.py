"""The pytest kit's real-time backend (``ExternalBackend``) on a late machine: the lockstep frames.

The backend plays the robot around an external firmware in a thread paced by a
``PeriodicLoop``. A tick that started late sampled the vehicle when the thread got the CPU, and a
tick after skipped releases put all their motion under one COUNTER step, which a firmware bounds
by the robot's top speed (kobuki: 0.7 m/s a period) and refuses: a FAIL blaming a correct firmware.
As ``odocan sim`` does (tests/test_sim_late_ticks.py), the backend samples at each release and
sends a skipped release's sample late. The reference is independent of the real-time path: the
same SimNode driven in lockstep, tick k at k * 10 ms.
"""

from __future__ import annotations

import itertools
import math
import secrets
import threading

import can
import pytest

from odocan.host.testkit import backends
from odocan.host.testkit.options import RigOptions
from odocan.sim.board import TICK_S
from odocan.sim.clock import LockstepClock
from odocan.sim.motor_controller import SimNode
from odocan.sim.scenarios import get_scenario
from odocan.sim.vehicle import Vehicle
from tests.test_sim_late_ticks import _encoder_frames

SEED = 5
RELEASES = 300
# Release k starts this late (s): 4 ms (inside the period), 25 ms (two releases skipped), 13 ms
# (one skipped), 31 ms (three); every other release on time.
LATENESS_S = {5: 0.004, 40: 0.025, 90: 0.013, 150: 0.0095, 220: 0.031}


class LateClock:
    """A fake real-time clock: a release starts on time unless ``LATENESS_S`` names it. The
    loop's first sleep waits for ``go``; once it got to release ``RELEASES`` it stops there
    (``done``) until ``resume``: the test stops the loop meanwhile."""

    def __init__(self) -> None:
        self.t = 0.0
        self.calls = 0
        self.go, self.done, self.resume = threading.Event(), threading.Event(), threading.Event()

    def now_s(self) -> float:
        return self.t

    def sleep_until(self, t_s: float) -> float:
        if self.calls == 0:
            self.go.wait(10)
        if t_s >= RELEASES * TICK_S - 1e-9:
            self.done.set()
            self.resume.wait(10)
            return 0.0
        late = LATENESS_S.get(self.calls, 0.0)
        self.calls += 1
        self.t = max(self.t, t_s + late)
        return 0.0


def _lockstep_frames(options: RigOptions, channel: str) -> list[bytes]:
    with (
        can.Bus(interface="odocan", channel=channel) as tx,
        can.Bus(interface="odocan", channel=channel) as rx,
    ):
        clock = LockstepClock()
        vehicle = Vehicle(options.profile(), options.error_model(), seed=options.seed)
        node = SimNode(tx, vehicle, clock, None)
        node.set_scenario(get_scenario("random", options.profile(), SEED))
        for k in range(RELEASES):
            clock.advance_to(k * TICK_S)
            node.tick(k)
        return _encoder_frames(rx)


def test_the_real_time_backend_sends_the_lockstep_frames_of_its_releases(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    clock = LateClock()
    monkeypatch.setattr(backends, "RealTimeClock", lambda: clock)
    channel = f"kit-late-{secrets.token_hex(4)}"
    options = RigOptions(robot="kobuki", seed=SEED)
    with can.Bus(interface="odocan", channel=channel) as rx:
        backend = backends.ExternalBackend(options, {"interface": "odocan", "channel": channel})
        try:
            backend.set_scenario(get_scenario("random", options.profile(), SEED))
            clock.go.set()
            assert clock.done.wait(60)
            backend._loop.request_stop()
        finally:
            clock.resume.set()
            backend.close()
        heard = _encoder_frames(rx)
    assert backend._loop.stats.skipped_releases == 2 + 1 + 3  # the premise: releases skipped
    # One encoder frame per release, the skipped ones' sent late: COUNTER +1 each, as the DBC says.
    assert len(heard) == RELEASES
    assert all((b[1] - a[1]) & 0xF == 1 for a, b in itertools.pairwise(heard))
    reference = _lockstep_frames(options, f"{channel}-ref")
    # Until the first skip the commands are the same: every frame is the lockstep one, byte for
    # byte, though release 5 ran 4 ms late (sampled then, it held 1.4 periods of motion).
    for k in range(41):
        assert heard[k] == reference[k], f"release {k}: {heard[k].hex()} != {reference[k].hex()}"
    # After it, each wheel's step stays within one period's motion at kobuki's 0.7 m/s.
    per_period = math.ceil(0.7 * TICK_S / (2 * math.pi * 0.035 / 2578)) + 1
    for k, (a, b) in enumerate(itertools.pairwise(heard), start=1):
        for lo in (2, 5):  # LEFT_COUNT, RIGHT_COUNT (u24, 16-bit counters)
            step = int.from_bytes(b[lo:lo + 3], "little") - int.from_bytes(a[lo:lo + 3], "little")
            step = (step + 0x8000) % 0x10000 - 0x8000
            assert abs(step) <= per_period, f"release {k}: {step} counts in one period"
