"""Error model: E_d and E_b change the actual robot as specified; slip; the parser."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from odocan.sim.errors import ErrorModel, ErrorModelError, parse
from odocan.sim.robot import load
from odocan.sim.vehicle import Vehicle

TAU = 0.05


@given(ed=st.floats(0.5, 2.0))
def test_ed_sets_the_diameter_ratio_and_keeps_the_mean(ed: float) -> None:
    profile = load("kobuki")
    left, right = ErrorModel(ed=ed).actual_radii_m(profile)
    assert right / left == pytest.approx(ed, rel=1e-15)
    assert 0.5 * (left + right) == pytest.approx(0.035, rel=1e-15)
    assert left == pytest.approx(0.035 * 2 / (ed + 1), rel=1e-15)


def test_no_error_is_the_nominal_robot_exactly() -> None:
    profile = load("pmir")
    model = ErrorModel()
    assert model.actual_radii_m(profile) == (0.075, 0.075)
    assert model.actual_wheelbase_m(profile) == 0.3


def test_eb_scales_the_wheelbase() -> None:
    assert ErrorModel(eb=1.01).actual_wheelbase_m(load("pmir")) == pytest.approx(0.303, rel=1e-15)


def straight_run(errors: ErrorModel, left: float, right: float, t_end: float) -> Vehicle:
    """pmir commanded at constant wheel speeds (re-commanded every 10 ms) until ``t_end``."""
    vehicle = Vehicle(load("pmir"), errors)
    for k in range(round(t_end * 100)):
        vehicle.command(left, right, k / 100)
    vehicle.advance_to(t_end)
    return vehicle


def test_ed_bends_a_commanded_straight_line_into_a_known_arc() -> None:
    """Equal commands, vR/vL = E_d: curvature 2(E_d-1)/(b(E_d+1)) whatever the speed profile."""
    ed = 1.02
    pose = straight_run(ErrorModel(ed=ed), 0.05, 0.05, 2.0).truth()
    kappa = 2 * (ed - 1) / (0.3 * (ed + 1))
    s = 0.05 * (2.0 - TAU * (1 - math.exp(-2.0 / TAU)))  # mean diameter kept: nominal distance
    assert pose.distance_m == pytest.approx(s, abs=1e-12)
    assert pose.heading_rad == pytest.approx(kappa * s, abs=1e-12)
    assert pose.x_m == pytest.approx(math.sin(kappa * s) / kappa, abs=1e-12)
    assert pose.y_m == pytest.approx((1 - math.cos(kappa * s)) / kappa, abs=1e-12)


def test_eb_changes_the_turn_rate_of_a_spin() -> None:
    eb = 1.05
    pose = straight_run(ErrorModel(eb=eb), -0.05, 0.05, 1.0).truth()
    s = 0.05 * (1.0 - TAU * (1 - math.exp(-1.0 / TAU)))
    assert pose.heading_rad == pytest.approx(2 * s / (0.3 * eb), abs=1e-12)
    assert (pose.x_m, pose.y_m) == (0.0, 0.0)


def test_slip_noise_has_the_stated_spread() -> None:
    ds = np.ones((200_000, 2))
    ground = ErrorModel(slip=0.01).apply_slip(ds, np.random.default_rng(3))
    assert ground.mean() == pytest.approx(1.0, abs=1e-4)
    assert ground.std() == pytest.approx(0.01, rel=0.02)
    assert abs(np.corrcoef(ground[:, 0], ground[:, 1])[0, 1]) < 0.01  # wheels independent


def test_no_slip_draws_nothing() -> None:
    rng = np.random.default_rng(3)
    ds = np.ones((5, 2))
    assert ErrorModel().apply_slip(ds, rng) is ds
    assert rng.standard_normal() == np.random.default_rng(3).standard_normal()


@pytest.mark.parametrize(
    ("text", "model"),
    [
        ("ed=1.002,eb=1.01,slip=0.01", ErrorModel(1.002, 1.01, 0.01)),
        (" slip = 0.02 , ed=0.99 ", ErrorModel(ed=0.99, slip=0.02)),
        ("", ErrorModel()),
        ("eb=1,", ErrorModel()),
    ],
)
def test_parse(text: str, model: ErrorModel) -> None:
    assert parse(text) == model


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("ed=1.0,foo=2", "unknown key 'foo' (known: ed, eb, slip)"),
        ("ed", "expected key=value, got 'ed'"),
        ("ed=abc", "ed='abc' is not a number"),
        ("ed=1,ed=1.1", "key 'ed' given twice"),
        ("ed=0", "ed=0.0 is outside 0.5..2.0"),
        ("eb=3", "eb=3.0 is outside 0.5..2.0"),
        ("slip=-0.1", "slip=-0.1 is outside 0.0..0.5"),
        ("slip=nan", "slip=nan is outside"),
    ],
)
def test_parse_errors(text: str, message: str) -> None:
    with pytest.raises(ErrorModelError) as info:
        parse(text)
    assert message in str(info.value)
    assert "\n" not in str(info.value)
