"""Robot profiles: shipped values, the nanometre grid, and every validation error."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from odocan.sim.robot import ProfileError, RobotProfile, list_profiles, load

VALID = {
    "counts_per_rev": "500",
    "wheel_radius_left_m": "0.075",
    "wheel_radius_right_m": "0.075",
    "wheelbase_m": "0.30",
    "counter_bits": "16",
}


def write_profile(tmp_path: Path, **overrides: str | None) -> Path:
    """A TOML profile from ``VALID`` with keys replaced (value) or removed (None)."""
    table = {**VALID, **overrides}
    lines = [f"{k} = {v}" for k, v in table.items() if v is not None]
    path = tmp_path / "robot.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def load_error(path: Path) -> str:
    """The one-line message of the ProfileError raised when loading ``path``."""
    with pytest.raises(ProfileError) as info:
        load(path)
    message = str(info.value)
    assert "\n" not in message
    return message


def test_list_profiles() -> None:
    assert list_profiles() == ["kobuki", "pmir"]


def test_pmir_is_seed_002_robot() -> None:
    p = load("pmir")
    assert p == RobotProfile("pmir", 500, 0.075, 0.075, 0.3, 16, 4.0)
    # seed 002 eq. 4: pi * 15 cm / 500 = 0.094 cm per pulse (0.09425, truncated in the paper)
    metres_per_pulse = 2 * math.pi * p.wheel_radius_left_m / p.counts_per_rev
    assert metres_per_pulse == pytest.approx(0.00094, abs=3e-6)


def test_kobuki() -> None:
    assert load("kobuki") == RobotProfile("kobuki", 2578, 0.035, 0.035, 0.23, 16, 0.7)


def test_firmware_params_are_integers_in_nm() -> None:
    params = load("kobuki").firmware_params()
    assert params == {
        "counts_per_rev": 2578,
        "wheel_radius_left_nm": 35_000_000,
        "wheel_radius_right_nm": 35_000_000,
        "wheelbase_nm": 230_000_000,
        "counter_bits": 16,
        "max_wheel_speed_mm_s": 700,
    }
    assert all(type(v) is int for v in params.values())


@pytest.mark.parametrize(
    ("given", "nm"),
    [("0.0350000004", 35_000_000), ("0.0350000006", 35_000_001), ("0.123456789", 123_456_789)],
)
def test_lengths_are_rounded_to_whole_nanometres(tmp_path: Path, given: str, nm: int) -> None:
    p = load(write_profile(tmp_path, wheel_radius_left_m=given, wheelbase_m=given))
    assert p.firmware_params()["wheel_radius_left_nm"] == nm
    assert p.firmware_params()["wheelbase_nm"] == nm
    assert p.wheel_radius_left_m == nm / 1e9
    assert p.wheelbase_m == nm / 1e9


def test_user_path_name_defaults_to_stem_and_can_be_given(tmp_path: Path) -> None:
    path = write_profile(tmp_path)
    assert load(path).name == "robot"
    assert load(str(path)).name == "robot"
    named = write_profile(tmp_path, name='"mybot"')
    assert load(named).name == "mybot"


def test_integer_radius_is_accepted(tmp_path: Path) -> None:
    assert load(write_profile(tmp_path, wheel_radius_left_m="1")).wheel_radius_left_m == 1.0


def test_profile_is_frozen() -> None:
    with pytest.raises(dataclasses.FrozenInstanceError):
        load("pmir").wheelbase_m = 1.0  # type: ignore[misc]


def test_unknown_name_lists_known() -> None:
    with pytest.raises(ProfileError, match=r"unknown robot 'nope' \(known: kobuki, pmir\)"):
        load("nope")


def test_missing_file(tmp_path: Path) -> None:
    assert "not found" in load_error(tmp_path / "absent.toml")


def test_a_directory_is_named_as_one(tmp_path: Path) -> None:
    """``--robot /tmp`` once said "file not found" for a directory that is there."""
    assert load_error(tmp_path) == f"robot profile {tmp_path} is a directory, not a TOML file"


def test_malformed_toml(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text("counts_per_rev = = 3\n")
    assert "malformed TOML" in load_error(path)


def test_missing_key(tmp_path: Path) -> None:
    msg = load_error(write_profile(tmp_path, wheelbase_m=None, counter_bits=None))
    assert "missing key(s): counter_bits, wheelbase_m" in msg


def test_extra_key(tmp_path: Path) -> None:
    assert "unknown key(s): colour" in load_error(write_profile(tmp_path, colour='"red"'))


@pytest.mark.parametrize(
    ("key", "value", "expected"),
    [
        ("wheel_radius_left_m", '"0.075"', "'wheel_radius_left_m' must be a number, got str"),
        ("wheelbase_m", "true", "'wheelbase_m' must be a number, got bool"),
        ("wheelbase_m", "nan", "'wheelbase_m' must be finite"),
        ("counts_per_rev", "500.0", "'counts_per_rev' must be an integer, got float"),
        ("counter_bits", "true", "'counter_bits' must be an integer, got bool"),
        ("name", "3", "'name' must be a non-empty string"),
    ],
)
def test_wrong_types(tmp_path: Path, key: str, value: str, expected: str) -> None:
    assert expected in load_error(write_profile(tmp_path, **{key: value}))


@pytest.mark.parametrize(
    ("key", "value", "expected"),
    [
        ("wheel_radius_left_m", "0.0", "'wheel_radius_left_m' must be positive"),
        ("wheel_radius_right_m", "-0.07", "'wheel_radius_right_m' must be positive"),
        ("wheel_radius_left_m", "0.0009", "is outside 0.001..2.0 m"),
        ("wheel_radius_right_m", "2.5", "is outside 0.001..2.0 m"),
        ("wheelbase_m", "0.009", "'wheelbase_m' = 0.009 m is outside 0.01..4.0 m"),
        ("wheelbase_m", "4.01", "is outside 0.01..4.0 m"),
        ("counts_per_rev", "0", "'counts_per_rev' = 0 is outside 1..2**24"),
        ("counts_per_rev", "16777217", "is outside 1..2**24"),
        ("counter_bits", "8", "'counter_bits' must be 16 or 32, got 8"),
    ],
)
def test_out_of_range(tmp_path: Path, key: str, value: str, expected: str) -> None:
    assert expected in load_error(write_profile(tmp_path, **{key: value}))


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("wheel_radius_left_m", "0.001"),
        ("wheel_radius_right_m", "2.0"),
        ("wheelbase_m", "0.01"),
        ("wheelbase_m", "4.0"),
        ("counts_per_rev", "1"),
        ("counts_per_rev", "16777216"),
        ("counter_bits", "32"),
    ],
)
def test_range_limits_are_inclusive(tmp_path: Path, key: str, value: str) -> None:
    wide = {"counter_bits": "32"} if key == "counts_per_rev" else {}  # 2^24 counts: 24-bit read
    if (key, value) == ("counts_per_rev", "1"):  # one count of a 75 mm wheel on 0.3 m: 90 deg
        wide |= {"wheel_radius_left_m": "0.001", "wheel_radius_right_m": "0.001"}
    profile = load(write_profile(tmp_path, **{**wide, key: value}))
    assert getattr(profile, key) == type(getattr(profile, key))(value)


@pytest.mark.parametrize(
    ("counts_per_rev", "radius_m", "bits", "readable_m_s"),
    [
        (2**24, 35e-3 / (2 * math.pi), 32, 0.875),  # 2^24 counts per 35 mm of circumference
        (2**24, 0.035, 16, 0.0215),  # a 16-bit counter wraps 1/256 of a turn
        (200_000, 0.035, 16, 1.8),
    ],
)
def test_a_robot_whose_steps_the_counters_cannot_read_is_refused(
    tmp_path: Path, counts_per_rev: int, radius_m: float, bits: int, readable_m_s: float
) -> None:
    """At the firmware's 4 m/s bound a step of two periods would wrap the counters as read (the
    hardware width, at most the wire's 24 bits): on board and on the host it would read as a
    smaller or backward step, so the profile is refused, naming the speed the counters read."""
    path = write_profile(tmp_path, counts_per_rev=str(counts_per_rev), counter_bits=str(bits),
                         wheel_radius_left_m=repr(radius_m), wheel_radius_right_m=repr(radius_m))
    message = load_error(path)
    # independent: two 10 ms periods at v move 2 v T / (2 pi r / counts) counts, < 2^(bits-1)
    limit_m_s = 2 ** (min(bits, 24) - 1) * 2 * math.pi * radius_m / counts_per_rev / 0.02
    assert limit_m_s == pytest.approx(readable_m_s, rel=2e-3)
    assert f"read wrapped above {readable_m_s:.3g} m/s" in message
    assert "below the firmware's 4 m/s bound" in message


@pytest.mark.parametrize(
    ("counts_per_rev", "radius_m", "bits"),
    [(2**24, 0.026, 32), (180_000, 0.035, 32), (90_000, 0.035, 16), (2578, 0.002, 16)],
)
def test_a_robot_the_counters_read_at_4_m_s_is_accepted(
    tmp_path: Path, counts_per_rev: int, radius_m: float, bits: int
) -> None:
    """Two periods at 4 m/s stay below half the range read: 2 * 0.04 m * counts / (2 pi r)."""
    assert 0.08 * counts_per_rev / (2 * math.pi * radius_m) < 2 ** (min(bits, 24) - 1) - 2
    path = write_profile(tmp_path, counts_per_rev=str(counts_per_rev), counter_bits=str(bits),
                         wheel_radius_left_m=repr(radius_m), wheel_radius_right_m=repr(radius_m))
    assert load(path).counts_per_rev == counts_per_rev


@pytest.mark.parametrize(
    ("counts_per_rev", "radius_m", "wheelbase_m"),
    [(12, 0.021, 0.01), (4, 0.075, 0.30), (1, 0.002, 0.01)],
)
def test_a_robot_one_count_turns_by_more_than_a_sixteenth_turn_is_refused(
    tmp_path: Path, counts_per_rev: int, radius_m: float, wheelbase_m: float
) -> None:
    """The firmware refuses such a profile at boot (FAULT, CONFIG_INVALID: one count would turn
    the robot by more than 1/16 turn), so the host must refuse it too instead of driving a board
    that never runs and calling its silent pose a FAIL. Independent: one count of one wheel turns
    the robot by (2 pi r / counts) / b rad."""
    turn_per_count = (2 * math.pi * radius_m / counts_per_rev) / wheelbase_m / (2 * math.pi)
    assert turn_per_count >= 1 / 16
    path = write_profile(tmp_path, counts_per_rev=str(counts_per_rev),
                         wheel_radius_left_m=repr(radius_m), wheel_radius_right_m=repr(radius_m),
                         wheelbase_m=repr(wheelbase_m))
    message = load_error(path)
    assert "1/16 turn" in message
    assert f"{turn_per_count * 360:.3g} deg" in message


def test_a_robot_one_count_turns_by_less_than_a_sixteenth_turn_is_accepted(tmp_path: Path) -> None:
    """(2 pi 0.005 / 24) / 0.01 rad = 0.13 rad, 1/48 turn: the firmware runs it."""
    path = write_profile(tmp_path, counts_per_rev="24", wheel_radius_left_m="0.005",
                         wheel_radius_right_m="0.005", wheelbase_m="0.01")
    assert load(path).counts_per_rev == 24
