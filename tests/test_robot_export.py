"""A profile written by ``to_toml`` loads back the same; its hash follows the firmware."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from odocan.sim.robot import RobotProfile, list_profiles, load, profile_sha256, to_toml


@pytest.mark.parametrize("name", list_profiles())
def test_a_shipped_profile_round_trips(name: str, tmp_path: Path) -> None:
    profile = load(name)
    path = tmp_path / "copy.toml"
    path.write_text(to_toml(profile))
    assert load(path) == profile


def test_an_odd_profile_round_trips_on_the_nanometre_grid(tmp_path: Path) -> None:
    odd = RobotProfile("odd \"one\"", 2**24, 0.032345679, 1.999999999, 0.010000001, 32)
    path = tmp_path / "odd.toml"
    path.write_text(to_toml(odd))
    loaded = load(path)
    assert loaded == odd
    assert loaded.firmware_params()["wheelbase_nm"] == 10_000_001


def test_the_hash_changes_with_what_the_firmware_receives_only() -> None:
    pmir = load("pmir")
    assert profile_sha256(dataclasses.replace(pmir, name="renamed")) == profile_sha256(pmir)
    wider = dataclasses.replace(pmir, wheelbase_m=pmir.wheelbase_m + 1e-9)
    assert profile_sha256(wider) != profile_sha256(pmir)
    assert len(profile_sha256(pmir)) == 64
