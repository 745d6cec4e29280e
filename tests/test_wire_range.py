"""A robot whose steps at the ECU's maximum wheel speed the counters cannot read is refused.

WHEEL_ENCODERS carries the low 24 bits of each counter, a 16-bit counter wraps at 2^16: a step of
half that range or more reads wrapped (``wrap_signed``), as a smaller or backward step that the
plausibility bound cannot tell from a true one. 2^24 counts per 35 mm of wheel circumference read
wrapped above 1.75 m/s, yet the firmware's 4 m/s bound accepted the configuration: the pose went
wrong on board and on the host alike, silently. ``validate_at_speed`` now refuses a
configuration in which a step of ``READABLE_PERIODS`` (2) periods at the ECU's bound could reach
half the readable range (WIRE_RANGE): the boot configuration is a FAULT, an ODOM_CONFIG a NACK.
"""

from __future__ import annotations

import dataclasses
import math
import random
from pathlib import Path

import pytest

from odocan.firmware import config, encoders
from odocan.firmware import frames as fr
from odocan.firmware.config import ConfigReason, RobotParams, validate, validate_at_speed
from odocan.firmware.encoders import MAX_WHEEL_SPEED_MM_S
from odocan.firmware.errors import ErrorFlag, State
from tests.odo_helpers import params
from tests.test_ecu import Rig, _config
from tests.test_outside_inputs import _one_error_line

# 2^24 counts per 35 mm of wheel circumference (radius 5.57 mm), 32-bit counters
FINE = params("exact", counts_per_rev=1 << 24, wheel_radius_left_nm=5_570_423,
              wheel_radius_right_nm=5_570_423, counter_bits=32)


def independent_refusal(p: RobotParams, speed_mm_s: int) -> bool | None:
    """Float: two 10 ms periods at v move 2 (v T / travel per count + 1) counts (the bound's
    ceiling and edge count), refused at half the range read; None within 1e-9 of the edge."""
    half = 2.0 ** (min(p.counter_bits, 24) - 1)
    worst = 0.0
    for radius_nm in (p.wheel_radius_left_nm, p.wheel_radius_right_nm):
        per_count_m = 2 * math.pi * radius_nm * 1e-9 / p.counts_per_rev
        worst = max(worst, 2 * (math.ceil(speed_mm_s * 1e-5 / per_count_m) + 1))
    if abs(worst - half) <= 2 + half * 1e-9:  # the ceiling may fall either side in float
        return None
    return worst >= half


def test_the_fine_robot_is_refused_at_4_m_s_and_accepted_at_a_speed_it_can_read() -> None:
    assert validate(FINE) is ConfigReason.OK  # every parameter in range on its own
    assert validate_at_speed(FINE, MAX_WHEEL_SPEED_MM_S) is ConfigReason.WIRE_RANGE
    assert validate_at_speed(FINE, 1_750) is ConfigReason.WIRE_RANGE  # one period reads right
    assert validate_at_speed(FINE, 800) is ConfigReason.OK  # two periods < 2^23 counts
    sixteen = dataclasses.replace(FINE, counter_bits=16)
    assert validate_at_speed(sixteen, 800) is ConfigReason.WIRE_RANGE  # 2^15 on the hardware


def test_the_refusal_agrees_with_a_float_count_of_two_periods() -> None:
    rng = random.Random(5)
    outcomes = [0, 0]
    for _ in range(3_000):
        p = RobotParams(
            counts_per_rev=round(2 ** rng.uniform(3.6, 24)),
            wheel_radius_left_nm=round(10 ** rng.uniform(6, 9.3)),
            wheel_radius_right_nm=round(10 ** rng.uniform(6, 9.3)),
            wheelbase_nm=4_000_000_000,
            counter_bits=rng.choice((16, 32)),
            integrator=2,
        )
        if validate(p) is not ConfigReason.OK:
            continue
        speed_mm_s = rng.choice((MAX_WHEEL_SPEED_MM_S, rng.randrange(1, 65_536)))
        expected = independent_refusal(p, speed_mm_s)
        if expected is None:
            continue
        got = validate_at_speed(p, speed_mm_s)
        assert (got is ConfigReason.WIRE_RANGE) == expected, (p, speed_mm_s)
        outcomes[expected] += 1
    assert min(outcomes) > 300  # both outcomes were met


def test_the_bound_is_the_encoder_inputs_own() -> None:
    rig = Rig(params("exact", counts_per_rev=1 << 20, counter_bits=32))
    per_count = rig.ecu.odometry.consts.m_per_count_left_q48_m
    got = config.max_counts_per_period(per_count, MAX_WHEEL_SPEED_MM_S, rig.ecu.errors)
    assert (got, got) == rig.ecu.encoders.step_bounds()
    assert config.WIRE_COUNTER_BITS == encoders.WIRE_COUNTER_BITS


def test_an_unreadable_boot_configuration_is_a_fault() -> None:
    rig = Rig(FINE)
    rig.drive(10, 1000, 1000, bits=32)
    assert rig.state() is State.FAULT
    assert rig.ecu.errors.has(ErrorFlag.CONFIG_INVALID)
    assert rig.ecu.odometry.x_q40_m == 0


def test_an_unreadable_odom_config_is_nacked_and_changes_nothing() -> None:
    rig = Rig(params("exact", counts_per_rev=1 << 24, counter_bits=32))  # 75 mm wheels: fine
    rig.drive(3)
    assert rig.state() is not State.FAULT
    before = rig.ecu.params
    _config(rig, fr.ConfigParam.WHEEL_RADIUS_LEFT, 5_570_423)
    ack = _config(rig, fr.ConfigParam.APPLY, 0)
    assert (ack["RESULT"], ack["REASON"]) == (fr.AckResult.NACK, fr.AckReason.INCONSISTENT)
    assert rig.ecu.params == before
    assert rig.ecu.errors.has(ErrorFlag.CONFIG_INVALID)


@pytest.mark.parametrize("bits", [16, 32])
def test_the_shipped_robots_and_the_issue_ranges_stay_usable(bits: int) -> None:
    """pmir and kobuki; and the issue's 2^24 counts per turn on a kobuki-size wheel (32-bit)."""
    kobuki = params("exact", counts_per_rev=2578, wheel_radius_left_nm=35_000_000,
                    wheel_radius_right_nm=35_000_000, wheelbase_nm=230_000_000)
    for p in (params("exact", counter_bits=bits), dataclasses.replace(kobuki, counter_bits=bits)):
        assert validate_at_speed(p, MAX_WHEEL_SPEED_MM_S) is ConfigReason.OK
    big = dataclasses.replace(kobuki, counts_per_rev=1 << 24, wheelbase_nm=10_000_000,
                              counter_bits=32)
    assert validate_at_speed(big, MAX_WHEEL_SPEED_MM_S) is ConfigReason.OK


@pytest.mark.parametrize("command", [["run", "--duration", "1"], ["analyze", "x.log"],
                                     ["vectors", "--out", "v"]])
def test_the_cli_refuses_such_a_robot_file_in_one_line(
    command: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "fine.toml"
    path.write_text("counts_per_rev = 16777216\nwheel_radius_left_m = 0.005570423\n"
                    "wheel_radius_right_m = 0.005570423\nwheelbase_m = 0.01\ncounter_bits = 32\n")
    err = _one_error_line(capsys, [*command, "--robot", str(path)])
    assert "read wrapped above 0.875 m/s" in err
    assert "below the firmware's 4 m/s bound" in err
