"""Open-loop driving scenarios: wheel rim-speed setpoints as a function of time.

Each scenario is a pure function of time (``command_at(t_s) -> (left_mps, right_mps)``) with a
natural ``default_duration_s`` (the manoeuvre plus a rest at the end so the robot has stopped).
Timings come from the NOMINAL geometry of the profile, as an open-loop controller would compute
them. The motor lag and acceleration limit, the 10 ms command grid and the robot's real errors
make the true path differ from the nominal one, which is the point of odometry: on an error-free
robot ``circle`` and ``square`` come home within a few mm and 0.3 degrees, but ``figure8`` ends
about 8.5 degrees off because its wheels stop from unequal speeds (0.48 and 0.32 m/s) and the
acceleration-limited ramps to rest cover different distances.

* ``straight``: 2 m at 0.5 m/s (seed 002 drove 1 m and 2 m lines).
* ``spin``: two turns in place, wheels at +-0.2 m/s.
* ``circle``: one counter-clockwise lap of radius 1 m at 0.5 m/s.
* ``square``: 0.8 m sides (seed 002's square) at 0.3 m/s, counter-clockwise, in-place 90-degree
  turns at +-0.1 m/s, a 0.5 s stop between phases so one phase does not bleed into the next.
* ``figure8``: a counter-clockwise lap then a clockwise lap of radius 0.75 m at 0.4 m/s.
* ``random``: smooth random wheel speeds, per wheel a sum of three sinusoids (periods 4-40 s,
  random phases) clipped to +-1 m/s, for 60 s, drawn from ``numpy.random.default_rng(seed)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from odocan.sim.exceptions import ConfigurationError
from odocan.sim.robot import RobotProfile

REST_S = 1.0  # standstill at the end of every scenario


class ScenarioError(ConfigurationError):
    """An unknown scenario name (one-line message listing the known ones)."""


class Scenario(Protocol):
    """A wheel-speed program: rim-speed setpoints (m/s) at any time t_s >= 0."""

    name: str
    default_duration_s: float

    def command_at(self, t_s: float) -> tuple[float, float]:
        """(left, right) rim-speed setpoints in m/s at time ``t_s`` (s)."""
        ...


@dataclass(frozen=True)
class Phase:
    """A constant (left, right) rim-speed setpoint held for ``duration_s`` seconds."""

    duration_s: float
    left_mps: float
    right_mps: float


class PhaseScenario:
    """A scenario made of consecutive constant-speed phases, then standstill."""

    def __init__(self, name: str, phases: list[Phase]) -> None:
        """Phases run back to back from t = 0; afterwards the setpoints are 0."""
        self.name = name
        self.phases = tuple(phases)
        self._ends = tuple(np.cumsum([p.duration_s for p in phases]).tolist())
        self.default_duration_s = (self._ends[-1] if phases else 0.0) + REST_S

    def command_at(self, t_s: float) -> tuple[float, float]:
        """Setpoints of the phase containing ``t_s`` (phases are half-open [start, end))."""
        for end, phase in zip(self._ends, self.phases, strict=True):
            if t_s < end:
                return (phase.left_mps, phase.right_mps) if t_s >= 0 else (0.0, 0.0)
        return (0.0, 0.0)


def _arc_speeds(speed_mps: float, radius_m: float, wheelbase_m: float) -> tuple[float, float]:
    """Wheel speeds for a centre speed on an arc of signed radius (> 0 turns left)."""
    half = 0.5 * wheelbase_m / radius_m
    return speed_mps * (1.0 - half), speed_mps * (1.0 + half)


def straight(profile: RobotProfile, distance_m: float = 2.0, speed_mps: float = 0.5) -> Scenario:
    """Drive ``distance_m`` straight ahead at ``speed_mps``."""
    return PhaseScenario("straight", [Phase(distance_m / speed_mps, speed_mps, speed_mps)])


def spin(profile: RobotProfile, turns: float = 2.0, wheel_mps: float = 0.2) -> Scenario:
    """Turn in place counter-clockwise by ``turns`` revolutions, wheels at -+``wheel_mps``."""
    duration = turns * 2.0 * math.pi * 0.5 * profile.wheelbase_m / wheel_mps
    return PhaseScenario("spin", [Phase(duration, -wheel_mps, wheel_mps)])


def circle(profile: RobotProfile, radius_m: float = 1.0, speed_mps: float = 0.5) -> Scenario:
    """One counter-clockwise lap of ``radius_m`` at centre speed ``speed_mps``."""
    left, right = _arc_speeds(speed_mps, radius_m, profile.wheelbase_m)
    return PhaseScenario("circle", [Phase(2.0 * math.pi * radius_m / speed_mps, left, right)])


def figure8(profile: RobotProfile, radius_m: float = 0.75, speed_mps: float = 0.4) -> Scenario:
    """A counter-clockwise lap then a clockwise lap, both of ``radius_m``."""
    lap = 2.0 * math.pi * radius_m / speed_mps
    left, right = _arc_speeds(speed_mps, radius_m, profile.wheelbase_m)
    return PhaseScenario("figure8", [Phase(lap, left, right), Phase(lap, right, left)])


def square(
    profile: RobotProfile,
    side_m: float = 0.8,
    speed_mps: float = 0.3,
    turn_mps: float = 0.1,
    pause_s: float = 0.5,
) -> Scenario:
    """Four sides of ``side_m`` with in-place 90-degree left turns, stops between phases."""
    turn_s = 0.5 * math.pi * 0.5 * profile.wheelbase_m / turn_mps
    stop = Phase(pause_s, 0.0, 0.0)
    phases: list[Phase] = []
    for _ in range(4):
        phases += [Phase(side_m / speed_mps, speed_mps, speed_mps), stop]
        phases += [Phase(turn_s, -turn_mps, turn_mps), stop]
    return PhaseScenario("square", phases)


class RandomScenario:
    """Smooth random wheel speeds: per wheel a sum of three sinusoids, clipped to +-``max_mps``."""

    def __init__(self, seed: int, duration_s: float = 60.0, max_mps: float = 1.0) -> None:
        """Draw amplitudes (sum <= 1.2 * max_mps), periods 4-40 s and phases from ``seed``."""
        rng = np.random.default_rng(seed)
        self.name = "random"
        self.max_mps = max_mps
        self.duration_s = duration_s
        self.default_duration_s = duration_s + REST_S
        self._amp = rng.uniform(0.2, 0.4, size=(2, 3)) * max_mps
        self._omega = 2.0 * math.pi / rng.uniform(4.0, 40.0, size=(2, 3))
        self._phase = rng.uniform(0.0, 2.0 * math.pi, size=(2, 3))
        # Per wheel its (amplitude, rad/s, rad) x 3 as Python floats: command_at runs every
        # 20 ms, and six scalar sines cost a fraction of the numpy calls on a (2, 3) array.
        self._left, self._right = (
            _SineSum(*(v for term in zip(a, w, p, strict=True) for v in term))
            for a, w, p in zip(
                self._amp.tolist(), self._omega.tolist(), self._phase.tolist(), strict=True
            )
        )

    def command_at(self, t_s: float) -> tuple[float, float]:
        """Setpoints at ``t_s``; 0 before 0 and after ``duration_s``.

        The same IEEE operations in the same order as numpy's ``np.clip((amp * np.sin(omega *
        t + phase)).sum(axis=1), -max, max)``, so the same bits (tests/test_sim_scenarios.py
        checks it against that expression)."""
        if not 0.0 <= t_s < self.duration_s:
            return (0.0, 0.0)
        top = self.max_mps
        left, right = self._left.at(t_s), self._right.at(t_s)
        return min(max(left, -top), top), min(max(right, -top), top)


@dataclass(frozen=True, slots=True)
class _SineSum:
    """``(a0 sin(w0 t + p0) + a1 sin(w1 t + p1)) + a2 sin(w2 t + p2)``: amplitudes m/s,
    angular frequencies rad/s, phases rad."""

    a0: float
    w0: float
    p0: float
    a1: float
    w1: float
    p1: float
    a2: float
    w2: float
    p2: float

    def at(self, t_s: float) -> float:
        """The sum at ``t_s`` (s), folded left to right as numpy's 3-term ``sum`` does."""
        sin = math.sin
        first = self.a0 * sin(self.w0 * t_s + self.p0) + self.a1 * sin(self.w1 * t_s + self.p1)
        return first + self.a2 * sin(self.w2 * t_s + self.p2)


SCENARIOS: tuple[str, ...] = ("straight", "spin", "circle", "square", "figure8", "random")


def get_scenario(
    name: str, profile: RobotProfile, seed: int = 0, duration_s: float | None = None
) -> Scenario:
    """The scenario ``name`` for ``profile`` (``seed`` is used by ``random`` only).

    ``duration_s``: how long the run will last; ``random`` then drives until ``REST_S`` before
    its end (the others are fixed programs and come to rest when done).
    """
    builders = {
        "straight": straight,
        "spin": spin,
        "circle": circle,
        "square": square,
        "figure8": figure8,
    }
    if name == "random":
        if duration_s is not None and duration_s > REST_S:
            return RandomScenario(seed, duration_s=duration_s - REST_S)
        return RandomScenario(seed)
    if name not in builders:
        raise ScenarioError(f"unknown scenario {name!r} (known: {', '.join(SCENARIOS)})")
    return builders[name](profile)
