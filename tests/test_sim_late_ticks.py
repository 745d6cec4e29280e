"""`odocan sim` on a late machine: its encoder frames are the lockstep sim's, slot for slot.

A real-time tick that starts late (the OS gave the CPU late) or after skipped releases must not put
more than its periods' motion under one COUNTER step: a firmware bounds one period's step by the
robot's top speed, and refused such frames (kobuki on udp_multicast under load: hundreds of frames
refused, DEGRADED COUNTER_RESET, the pose 0.3 m off, every judge FAILing a correct firmware). The
reference here is independent of the real-time path: the same SimNode driven in lockstep, tick k at
k * 10 ms, whose frames the rig has always sent.
"""

from __future__ import annotations

import argparse
import itertools
import math
import secrets
from typing import Any

import can
import pytest

from odocan.firmware import frames as fr
from odocan.host.cli.subparsers import sim as sim_cli
from odocan.sim import robot
from odocan.sim.board import TICK_S
from odocan.sim.clock import LockstepClock
from odocan.sim.motor_controller import SimNode
from odocan.sim.realtime import PeriodicLoop

SEED = 7
DURATION_S = 3.0
# Release k starts this late (s): 4 ms (inside the period), 25 ms (two releases skipped), 13 ms
# (one skipped, then 3 ms late); every other release on time.
LATENESS_S = {5: 0.004, 40: 0.025, 41: 0.001, 90: 0.013, 150: 0.0095, 220: 0.031}


class LateClock:
    """A fake real-time clock: a release starts on time unless ``LATENESS_S`` names it."""

    def __init__(self) -> None:
        self.t = 0.0
        self.calls = 0

    def now_s(self) -> float:
        return self.t

    def sleep_until(self, t_s: float) -> float:
        late = LATENESS_S.get(self.calls, 0.0)
        self.calls += 1
        self.t = max(self.t, t_s + late)
        return max(0.0, self.t - t_s - late)


def _encoder_frames(bus: can.BusABC) -> list[bytes]:
    out = []
    msg = bus.recv(0)
    while msg is not None:
        if msg.arbitration_id == fr.WHEEL_ENCODERS_ID:
            out.append(bytes(msg.data))
        msg = bus.recv(0)
    return out


def _lockstep_frames(channel: str, ticks: int) -> list[bytes]:
    with (
        can.Bus(interface="odocan", channel=channel) as tx,
        can.Bus(interface="odocan", channel=channel) as rx,
    ):
        clock = LockstepClock()
        node = SimNode.build(tx, robot.load("kobuki"), clock, scenario="random", seed=SEED)
        for k in range(ticks):
            clock.advance_to(k * TICK_S)
            node.tick(k)
        return _encoder_frames(rx)


def test_a_late_real_time_sim_sends_the_lockstep_frames_of_its_slots(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    channel = f"late-{secrets.token_hex(4)}"
    ran: list[int] = []

    class RecordingLoop(PeriodicLoop):
        def __init__(self) -> None:
            super().__init__(clock=LateClock())  # type: ignore[arg-type]

        def run(self, tick: Any, duration_s: float | None = None) -> Any:
            def recorded(k: int) -> None:
                ran.append(k)
                tick(k)

            return super().run(recorded, duration_s)

    def open_odocan(args: argparse.Namespace, **_: Any) -> can.BusABC:
        return can.Bus(interface="odocan", channel=channel)

    monkeypatch.setattr(sim_cli, "PeriodicLoop", RecordingLoop)
    monkeypatch.setattr(sim_cli, "open_bus", open_odocan)
    args = argparse.Namespace(robot="kobuki", errors="", duration=DURATION_S,
                              scenario="random", seed=SEED)
    with can.Bus(interface="odocan", channel=channel) as rx:
        assert sim_cli._do_sim(args) == 0
        heard = _encoder_frames(rx)
    skipped = sorted(set(range(ran[-1] + 1)) - set(ran))
    assert skipped == [40, 41, 92, 223, 224, 225]  # the premise: the loop did skip releases
    # One encoder frame per release, the skipped ones' sent late: COUNTER +1 each, as the DBC says.
    assert len(heard) == ran[-1] + 1
    assert all((b[1] - a[1]) & 0xF == 1 for a, b in itertools.pairwise(heard))
    reference = _lockstep_frames(f"{channel}-ref", ran[-1] + 1)
    # Until the first skip the commands are the same: every frame is the lockstep one, byte for
    # byte, though release 5 ran 4 ms late (sampled then, it held 1.4 periods of motion).
    for k in range(40):
        assert heard[k] == reference[k], f"release {k}: {heard[k].hex()} != {reference[k].hex()}"
    # After a skip (its driver command was not sent, so the physics may part from the lockstep
    # run): each wheel's step stays within the firmware's one-period bound at kobuki's 0.7 m/s,
    # ceil(v T / (2 pi r / counts)) + 1 counts (independent of the firmware's code).
    per_period = math.ceil(0.7 * TICK_S / (2 * math.pi * 0.035 / 2578)) + 1
    assert per_period == 84
    for k, (a, b) in enumerate(itertools.pairwise(heard), start=1):
        for lo in (2, 5):  # LEFT_COUNT, RIGHT_COUNT (u24, 16-bit counters)
            step = int.from_bytes(b[lo:lo + 3], "little") - int.from_bytes(a[lo:lo + 3], "little")
            step = (step + 0x8000) % 0x10000 - 0x8000
            assert abs(step) <= per_period, f"release {k}: {step} counts in one period"
