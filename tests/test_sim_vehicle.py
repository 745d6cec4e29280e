"""The vehicle: time grid, determinism, lazy truth, and the whole chain against closed forms."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from odocan.sim.errors import ErrorModel
from odocan.sim.robot import load
from odocan.sim.scenarios import get_scenario
from odocan.sim.vehicle import Vehicle, VehicleError

TAU = 0.05


def run(vehicle: Vehicle, name: str, seed: int = 0, observe: bool = False) -> list[object]:
    """Drive scenario ``name`` at 100 Hz; the log of encoder counts (and truth if ``observe``)."""
    scenario = get_scenario(name, vehicle.profile, seed)
    log: list[object] = []
    for k in range(round(scenario.default_duration_s * 100) + 1):
        t = k / 100
        vehicle.command(*scenario.command_at(t), t)
        log.append(vehicle.encoder_counts())
        if observe:
            log.append(vehicle.truth())
    return log


def test_same_seed_same_output_bit_for_bit() -> None:
    errors = ErrorModel(ed=1.003, eb=0.99, slip=0.02)
    a = Vehicle(load("kobuki"), errors, seed=11)
    b = Vehicle(load("kobuki"), errors, seed=11)
    assert run(a, "random", seed=5) == run(b, "random", seed=5)
    assert a.truth() == b.truth()


def test_seed_changes_the_slip_but_not_the_encoders() -> None:
    errors = ErrorModel(slip=0.02)
    a = Vehicle(load("kobuki"), errors, seed=1)
    b = Vehicle(load("kobuki"), errors, seed=2)
    assert run(a, "square") == run(b, "square")  # slip is under the wheel, not on the shaft
    assert a.truth().x_m != b.truth().x_m


def test_observing_the_truth_does_not_change_it() -> None:
    errors = ErrorModel(ed=1.01, slip=0.01)
    watched = Vehicle(load("pmir"), errors, seed=4, trace_hz=100)
    unwatched = Vehicle(load("pmir"), errors, seed=4, trace_hz=100)
    log = run(watched, "figure8", observe=True)
    run(unwatched, "figure8")
    assert watched.truth() == unwatched.truth()
    assert log[-1] == unwatched.truth()
    for a, b in zip(
        dataclasses.astuple(watched.truth_trace()),
        dataclasses.astuple(unwatched.truth_trace()),
        strict=True,
    ):
        assert np.array_equal(a, b)


def test_trace_samples_the_truth() -> None:
    vehicle = Vehicle(load("pmir"), trace_hz=100)
    log = run(vehicle, "circle", observe=True)
    trace = vehicle.truth_trace()
    poses = log[1::2]
    assert trace.t_s.size == len(poses)
    for i in (0, 100, len(poses) - 1):
        pose = poses[i]
        assert isinstance(pose, type(vehicle.truth()))
        assert (trace.t_s[i], trace.x_m[i], trace.y_m[i]) == (pose.t_s, pose.x_m, pose.y_m)
        assert trace.heading_rad[i] == pytest.approx(pose.heading_rad, abs=1e-15)


def test_step_response_distance_through_the_whole_chain() -> None:
    """From rest, 0.05 m/s (limit inactive): s(t) = v (t - tau (1 - exp(-t/tau)))."""
    vehicle = Vehicle(load("kobuki"))
    vehicle.command(0.05, 0.05, 0.0)
    for t in (0.013, 0.1, 0.25, 0.49):
        vehicle.advance_to(t)
        pose = vehicle.truth()
        assert pose.t_s == t
        s = 0.05 * (t - TAU * (1 - math.exp(-t / TAU)))
        assert pose.x_m == pytest.approx(s, abs=1e-13)
        assert pose.distance_m == pytest.approx(s, abs=1e-13)
        assert vehicle.wheel_speeds_mps()[0] == pytest.approx(0.05 * (1 - math.exp(-t / TAU)))


def test_finer_substeps_converge() -> None:
    """The arc-per-substep model converges: 1 kHz and 8 kHz agree to under a micrometre."""
    coarse = Vehicle(load("pmir"), substep_hz=1000)
    fine = Vehicle(load("pmir"), substep_hz=8000)
    run(coarse, "random", seed=3)
    run(fine, "random", seed=3)
    a, b = coarse.truth(), fine.truth()
    assert math.hypot(a.x_m - b.x_m, a.y_m - b.y_m) < 1e-6
    assert a.heading_rad == pytest.approx(b.heading_rad, abs=1e-7)
    assert coarse.encoder_counts() == fine.encoder_counts()


def test_quadrature_counts_four_times_finer() -> None:
    x1, x4 = Vehicle(load("pmir")), Vehicle(load("pmir"), quadrature=True)
    for v in (x1, x4):
        v.command(0.3, -0.2, 0.0)
        v.advance_to(0.4)
    for a, b in zip(x1.encoder_counts(), x4.encoder_counts(), strict=True):
        assert a == 0 or abs(a) > 10
        assert (b - 4 * a) % 65536 < 4  # floor(4u) = 4 floor(u) + 0..3, wrapped


def test_time_is_on_the_substep_grid() -> None:
    vehicle = Vehicle(load("pmir"))
    vehicle.advance_to(0.3)  # 0.3 * 1000 = 299.99999999999994 in floats
    assert vehicle.t_s == 0.3
    vehicle.advance_to(0.3005)
    assert vehicle.t_s == 0.3


def test_time_cannot_run_backwards() -> None:
    vehicle = Vehicle(load("pmir"))
    vehicle.advance_to(1.0)
    with pytest.raises(VehicleError, match="time runs backwards"):
        vehicle.command(0.1, 0.1, 0.99)
    with pytest.raises(VehicleError, match="finite"):
        vehicle.advance_to(math.nan)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"substep_hz": 500}, "substep_hz must be an integer >= 1000"),
        ({"substep_hz": 1000.0}, "substep_hz must be an integer"),
        ({"trace_hz": 300}, "trace_hz must be 0 or divide 1000"),
    ],
)
def test_configuration_errors(kwargs: dict[str, float], message: str) -> None:
    with pytest.raises(VehicleError, match=message):
        Vehicle(load("pmir"), **kwargs)  # type: ignore[arg-type]


def test_actual_geometry_is_exposed() -> None:
    vehicle = Vehicle(load("pmir"), ErrorModel(ed=1.5, eb=1.1))
    assert vehicle.actual_radii_m == pytest.approx((0.06, 0.09))
    assert vehicle.actual_wheelbase_m == pytest.approx(0.33)
