"""Open-loop scenarios: nominal geometry of the programs, and what the robot does with them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from odocan.sim.pose import wrap_angle
from odocan.sim.robot import RobotProfile, load
from odocan.sim.scenarios import (
    SCENARIOS,
    PhaseScenario,
    RandomScenario,
    ScenarioError,
    get_scenario,
)
from odocan.sim.truth import TruthPose
from odocan.sim.vehicle import Vehicle

PROFILES = ["pmir", "kobuki"]


def integrate(name: str, profile: RobotProfile) -> tuple[float, float]:
    """Nominal (centre distance, heading change) of a phase scenario, summed phase by phase."""
    scenario = get_scenario(name, profile)
    assert isinstance(scenario, PhaseScenario)
    distance = heading = 0.0
    for p in scenario.phases:
        distance += 0.5 * (p.left_mps + p.right_mps) * p.duration_s
        heading += (p.right_mps - p.left_mps) / profile.wheelbase_m * p.duration_s
    return distance, heading


def drive(name: str, profile: RobotProfile, seed: int = 0) -> TruthPose:
    """Run scenario ``name`` at 100 Hz commands on an error-free robot; the final true pose."""
    scenario = get_scenario(name, profile, seed)
    vehicle = Vehicle(profile)
    for k in range(round(scenario.default_duration_s * 100) + 1):
        vehicle.command(*scenario.command_at(k / 100), k / 100)
    return vehicle.truth()


def test_names() -> None:
    assert SCENARIOS == ("straight", "spin", "circle", "square", "figure8", "random")


def test_unknown_name_lists_the_known_ones() -> None:
    with pytest.raises(ScenarioError, match=r"unknown scenario 'zigzag' \(known: straight, spin,"):
        get_scenario("zigzag", load("pmir"))


@pytest.mark.parametrize("name", SCENARIOS)
def test_every_scenario_ends_at_rest(name: str) -> None:
    scenario = get_scenario(name, load("pmir"), seed=1)
    assert scenario.name == name
    assert scenario.default_duration_s > 1.0
    assert scenario.command_at(scenario.default_duration_s - 0.5) == (0.0, 0.0)
    assert scenario.command_at(-1.0) == (0.0, 0.0)


@pytest.mark.parametrize("profile_name", PROFILES)
@pytest.mark.parametrize(
    ("name", "distance", "heading"),
    [
        ("straight", 2.0, 0.0),
        ("spin", 0.0, 4 * math.pi),
        ("circle", 2 * math.pi, 2 * math.pi),
        ("square", 3.2, 2 * math.pi),
        ("figure8", 3 * math.pi, 0.0),
    ],
)
def test_nominal_geometry(profile_name: str, name: str, distance: float, heading: float) -> None:
    d, h = integrate(name, load(profile_name))
    assert d == pytest.approx(distance, abs=1e-12)
    assert h == pytest.approx(heading, abs=1e-12)


def test_square_turns_are_quarter_turns_in_place() -> None:
    profile = load("pmir")
    scenario = get_scenario("square", profile)
    assert isinstance(scenario, PhaseScenario)
    turns = [p for p in scenario.phases if p.left_mps == -p.right_mps != 0]
    assert len(turns) == 4
    for p in turns:
        assert p.right_mps * 2 / profile.wheelbase_m * p.duration_s == pytest.approx(math.pi / 2)


@pytest.mark.parametrize("profile_name", PROFILES)
@pytest.mark.parametrize(("name", "tolerance_m"), [("circle", 0.01), ("square", 0.02)])
def test_closed_paths_come_home(profile_name: str, name: str, tolerance_m: float) -> None:
    pose = drive(name, load(profile_name))
    assert math.hypot(pose.x_m, pose.y_m) < tolerance_m
    assert abs(wrap_angle(pose.heading_rad)) < math.radians(1.0)


def test_straight_drives_two_metres_ahead() -> None:
    pose = drive("straight", load("kobuki"))
    assert pose.x_m == pytest.approx(2.0, abs=1e-9)  # symmetric start/stop lag: no loss
    assert (pose.y_m, pose.heading_rad) == (0.0, 0.0)


def test_random_is_seeded_bounded_and_smooth() -> None:
    profile = load("pmir")
    times = np.arange(0, 6000) / 100
    a = np.array([get_scenario("random", profile, 1).command_at(t) for t in times])
    b = np.array([get_scenario("random", profile, 1).command_at(t) for t in times])
    c = np.array([get_scenario("random", profile, 2).command_at(t) for t in times])
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    assert np.abs(a).max() <= 1.0
    assert np.abs(a).max() > 0.3  # really moves
    assert np.abs(np.diff(a, axis=0)).max() < 0.02  # < 2 m/s^2 at 100 Hz
    assert np.std(a[:, 0] - a[:, 1]) > 0.05  # it turns, too


def test_random_commands_are_the_bits_of_the_numpy_expression() -> None:
    """The scalar ``command_at`` against the numpy expression it replaced, on the rig's 20 ms
    grid (an hour) and at arbitrary instants; seed 7 drives into the +-1 m/s clip."""
    clipped = 0
    for seed in (0, 7):
        scenario = RandomScenario(seed, duration_s=3600.0)
        amp, omega, phase = scenario._amp, scenario._omega, scenario._phase
        rng = np.random.default_rng(seed)
        times = [k * 0.02 for k in range(180_000)] + rng.uniform(0.0, 3600.0, 20_000).tolist()
        for t_s in times:
            raw = (amp * np.sin(omega * t_s + phase)).sum(axis=1)
            want = [float(v).hex() for v in np.clip(raw, -1.0, 1.0)]
            got = scenario.command_at(t_s)
            assert [v.hex() for v in got] == want, (seed, t_s)
            clipped += any(abs(v) == 1.0 for v in got)
    assert clipped > 500  # the clip was exercised
