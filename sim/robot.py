"""Robot profiles: the nominal geometry the firmware is configured with, read from TOML.

A profile is the robot as its maker specifies it (the *nominal* geometry). The firmware holds
lengths as integer nanometres, so on load every length is rounded to a whole number of
nanometres and the float metres are set to the nearest double of that integer (``nm / 1e9``):
the float reference and the firmware then describe the very same robot. The real robot's
deviations from nominal (unequal diameters, wheelbase error, slip) live in ``sim.errors``.

Shipped profiles live in ``sim/robots/<name>.toml``::

    name = "pmir"                # optional, defaults to the file stem
    counts_per_rev = 500         # encoder counts per wheel revolution (x1 decoding), 1 .. 2**24
    wheel_radius_left_m = 0.075  # 0.001 .. 2 m
    wheel_radius_right_m = 0.075
    wheelbase_m = 0.30           # distance between the wheel contact points, 0.01 .. 4 m
    counter_bits = 16            # width of the free-running encoder counters: 16 or 32
    max_wheel_speed_m_s = 4.0    # optional: the fastest rim speed either wheel can reach,
                                 # 0.001 .. 65.535 m/s on the 1 mm/s grid (default 4.0)

``max_wheel_speed_m_s`` is the firmware's plausibility bound (an encoder step beyond it over its
periods is refused), the judges' bound on what a gap or a stall may hide, and the simulated motor
controller's saturation (a setpoint beyond it is clamped, as a real controller saturates).
"""

from __future__ import annotations

import hashlib
import json
import math
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from odocan.firmware.config import (
    ENCODER_PERIOD_US,
    MAX_WHEEL_SPEED_DEFAULT_MM_S,
    MAX_WHEEL_SPEED_MAX_MM_S,
    MAX_WHEEL_SPEED_MIN_MM_S,
    READABLE_PERIODS,
    WIRE_COUNTER_BITS,
    ConfigReason,
    RobotParams,
    validate_at_speed,
)
from odocan.sim.exceptions import ConfigurationError

ROBOTS_DIR = Path(str(resources.files("odocan.sim").joinpath("robots")))
NM_PER_M = 1_000_000_000

_RADIUS_RANGE_M = (0.001, 2.0)
_WHEELBASE_RANGE_M = (0.01, 4.0)
_CPR_RANGE = (1, 2**24)
_COUNTER_BITS = (16, 32)
_FLOAT_KEYS = ("wheel_radius_left_m", "wheel_radius_right_m", "wheelbase_m")
_INT_KEYS = ("counts_per_rev", "counter_bits")
_REQUIRED_KEYS = frozenset(_FLOAT_KEYS + _INT_KEYS)
_OPTIONAL_KEYS = frozenset({"name", "max_wheel_speed_m_s"})
MM_PER_M = 1000
DEFAULT_MAX_WHEEL_SPEED_M_S = MAX_WHEEL_SPEED_DEFAULT_MM_S / MM_PER_M  # 4.0 m/s
_SPEED_RANGE_M_S = (MAX_WHEEL_SPEED_MIN_MM_S / MM_PER_M, MAX_WHEEL_SPEED_MAX_MM_S / MM_PER_M)


class ProfileError(ConfigurationError):
    """A robot profile could not be found, parsed or validated (one-line message)."""


def _nm(length_m: float) -> int:
    """Round a length in metres to whole nanometres (round half to even)."""
    return round(length_m * NM_PER_M)


def _metres(length_nm: int) -> float:
    """The double nearest to ``length_nm`` nanometres (correctly rounded)."""
    return length_nm / NM_PER_M


@dataclass(frozen=True)
class RobotProfile:
    """Nominal geometry of a differential-drive robot, lengths on the 1 nm grid.

    Attributes:
        name: profile name.
        counts_per_rev: encoder counts per wheel revolution with x1 decoding, 1 .. 2**24.
        wheel_radius_left_m, wheel_radius_right_m: nominal wheel radii, 0.001 .. 2 m, each
            exactly ``nm / 1e9`` for an integer ``nm``.
        wheelbase_m: nominal distance between the wheel contact points, 0.01 .. 4 m, on the nm grid.
        counter_bits: width of the free-running unsigned encoder counters, 16 or 32.
        max_wheel_speed_m_s: the fastest rim speed either wheel can reach, 0.001 .. 65.535 m/s,
            exactly ``mm / 1e3`` for an integer ``mm`` (default 4.0).
    """

    name: str
    counts_per_rev: int
    wheel_radius_left_m: float
    wheel_radius_right_m: float
    wheelbase_m: float
    counter_bits: int
    max_wheel_speed_m_s: float = DEFAULT_MAX_WHEEL_SPEED_M_S

    @property
    def max_wheel_speed_mm_s(self) -> int:
        """The speed bound as the firmware holds it (u16 mm/s)."""
        return round(self.max_wheel_speed_m_s * MM_PER_M)

    def firmware_params(self) -> dict[str, int]:
        """The integers the firmware is configured with (lengths in nanometres)."""
        return {
            "counts_per_rev": self.counts_per_rev,
            "wheel_radius_left_nm": _nm(self.wheel_radius_left_m),
            "wheel_radius_right_nm": _nm(self.wheel_radius_right_m),
            "wheelbase_nm": _nm(self.wheelbase_m),
            "counter_bits": self.counter_bits,
            "max_wheel_speed_mm_s": self.max_wheel_speed_mm_s,
        }


def to_toml(profile: RobotProfile) -> str:
    """The profile as a TOML file that ``load`` reads back to the very same profile (every float
    written as its shortest round-trip repr, so the nanometre grid is kept)."""
    return (
        f"name = {json.dumps(profile.name)}\n"
        f"counts_per_rev = {profile.counts_per_rev}\n"
        f"wheel_radius_left_m = {profile.wheel_radius_left_m!r}\n"
        f"wheel_radius_right_m = {profile.wheel_radius_right_m!r}\n"
        f"wheelbase_m = {profile.wheelbase_m!r}\n"
        f"counter_bits = {profile.counter_bits}\n"
        f"max_wheel_speed_m_s = {profile.max_wheel_speed_m_s!r}\n"
    )


def profile_sha256(profile: RobotProfile) -> str:
    """A fingerprint of the geometry the firmware is configured with (the integers it receives,
    not the file's spelling): two profiles with the same hash configure the same firmware."""
    params = json.dumps(profile.firmware_params(), sort_keys=True).encode()
    return hashlib.sha256(params).hexdigest()


def list_profiles() -> list[str]:
    """Names of the shipped profiles (``sim/robots/*.toml``), sorted."""
    return sorted(p.stem for p in ROBOTS_DIR.glob("*.toml"))


def load(name_or_path: str | Path) -> RobotProfile:
    """Load a profile by shipped name (``"pmir"``) or from a TOML file path.

    A ``Path``, or a string ending in ``.toml`` or containing a path separator, is a file path;
    anything else is a shipped name. Raises ``ProfileError`` with a one-line message.
    """
    text = str(name_or_path)
    if isinstance(name_or_path, Path) or text.endswith(".toml") or "/" in text or "\\" in text:
        path = Path(name_or_path)
        if path.is_dir():
            raise ProfileError(f"robot profile {path} is a directory, not a TOML file")
        if not path.is_file():
            raise ProfileError(f"robot profile file not found: {path}")
    else:
        known = list_profiles()
        if text not in known:
            raise ProfileError(f"unknown robot {text!r} (known: {', '.join(known)})")
        path = ROBOTS_DIR / f"{text}.toml"
    return _from_table(_read_toml(path), default_name=path.stem, source=str(path))


def _read_toml(path: Path) -> dict[str, Any]:
    """Parse a TOML file, turning decode errors into ``ProfileError``."""
    try:
        with path.open("rb") as f:
            return tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise ProfileError(f"malformed TOML in {path}: {exc}") from None
    except UnicodeDecodeError as exc:  # tomllib decodes the whole file before it parses
        raise ProfileError(f"malformed TOML in {path}: not UTF-8 text ({exc.reason} at byte "
                           f"{exc.start})") from None
    except OSError as exc:
        raise ProfileError(f"cannot read robot profile {path}: {exc.strerror}") from None


def _from_table(table: dict[str, Any], default_name: str, source: str) -> RobotProfile:
    """Validate a parsed TOML table and build the profile on the nanometre grid."""
    _check_keys(table, source)
    name = table.get("name", default_name)
    if not isinstance(name, str) or not name:
        raise ProfileError(f"{source}: 'name' must be a non-empty string")
    for key in _INT_KEYS:
        _check_int(table[key], key, source)
    for key in _FLOAT_KEYS:
        _check_float(table[key], key, source)
    speed_m_s = table.get("max_wheel_speed_m_s", DEFAULT_MAX_WHEEL_SPEED_M_S)
    _check_float(speed_m_s, "max_wheel_speed_m_s", source)
    _check_speed(speed_m_s, source)
    _check_values(table, source, speed_m_s)
    return RobotProfile(
        name=name,
        counts_per_rev=table["counts_per_rev"],
        wheel_radius_left_m=_metres(_nm(table["wheel_radius_left_m"])),
        wheel_radius_right_m=_metres(_nm(table["wheel_radius_right_m"])),
        wheelbase_m=_metres(_nm(table["wheelbase_m"])),
        counter_bits=table["counter_bits"],
        max_wheel_speed_m_s=round(speed_m_s * MM_PER_M) / MM_PER_M,
    )


def _check_speed(speed_m_s: float, source: str) -> None:
    """The speed bound within the firmware's u16 mm/s range, once on its 1 mm/s grid."""
    lo, hi = _SPEED_RANGE_M_S
    if not lo <= round(speed_m_s * MM_PER_M) / MM_PER_M <= hi:
        raise ProfileError(f"{source}: 'max_wheel_speed_m_s' = {speed_m_s} m/s is outside "
                           f"{lo:g}..{hi:g} m/s")


def _check_keys(table: dict[str, Any], source: str) -> None:
    """Refuse missing and unknown keys."""
    missing = sorted(_REQUIRED_KEYS - table.keys())
    if missing:
        raise ProfileError(f"{source}: missing key(s): {', '.join(missing)}")
    extra = sorted(table.keys() - _REQUIRED_KEYS - _OPTIONAL_KEYS)
    if extra:
        raise ProfileError(f"{source}: unknown key(s): {', '.join(extra)}")


def _check_int(value: object, key: str, source: str) -> None:
    """An integer, not a bool or a float."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise ProfileError(f"{source}: {key!r} must be an integer, got {type(value).__name__}")


def _check_float(value: object, key: str, source: str) -> None:
    """A finite number (TOML float or integer), not a bool."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ProfileError(f"{source}: {key!r} must be a number, got {type(value).__name__}")
    if not math.isfinite(value):
        raise ProfileError(f"{source}: {key!r} must be finite, got {value}")


def _check_values(table: dict[str, Any], source: str, speed_m_s: float) -> None:
    """Range checks, one clear message per failure."""
    lo, hi = _RADIUS_RANGE_M
    for key in ("wheel_radius_left_m", "wheel_radius_right_m"):
        value = table[key]
        if value <= 0:
            raise ProfileError(f"{source}: {key!r} must be positive, got {value}")
        if not lo <= value <= hi:
            raise ProfileError(f"{source}: {key!r} = {value} m is outside {lo}..{hi} m")
    lo, hi = _WHEELBASE_RANGE_M
    if not lo <= table["wheelbase_m"] <= hi:
        value = table["wheelbase_m"]
        raise ProfileError(f"{source}: 'wheelbase_m' = {value} m is outside {lo}..{hi} m")
    lo_c, hi_c = _CPR_RANGE
    if not lo_c <= table["counts_per_rev"] <= hi_c:
        value = table["counts_per_rev"]
        raise ProfileError(f"{source}: 'counts_per_rev' = {value} is outside 1..2**24")
    if table["counter_bits"] not in _COUNTER_BITS:
        value = table["counter_bits"]
        raise ProfileError(f"{source}: 'counter_bits' must be 16 or 32, got {value}")
    _check_readable(table, source, speed_m_s)


def _check_readable(table: dict[str, Any], source: str, speed_m_s: float) -> None:
    """The firmware's ``validate_at_speed``: at its maximum wheel speed a step of
    ``READABLE_PERIODS`` periods must stay below half the counters' readable range (their width,
    at most the wire's 24 bits), or its counts read wrapped on board and on the host alike.
    The speed it names is the firmware's, in its own ``ENCODER_PERIOD_US`` (not the DBC's
    WHEEL_ENCODERS cycle): the refusal is ``validate_at_speed``'s, so its figure must be the one
    that rule used (the two are held equal: tests/test_rig.py, cycle_us("WHEEL_ENCODERS"))."""
    nm = {key: _nm(table[key]) for key in _FLOAT_KEYS}
    speed_mm_s = round(speed_m_s * MM_PER_M)
    params = RobotParams(table["counts_per_rev"], nm["wheel_radius_left_m"],
                         nm["wheel_radius_right_m"], nm["wheelbase_m"], table["counter_bits"], 0,
                         speed_mm_s)
    reason = validate_at_speed(params, speed_mm_s)
    if reason is ConfigReason.GEOMETRY_ABSURD:
        _refuse_absurd_geometry(table, source)
    if reason is not ConfigReason.WIRE_RANGE:
        return
    bits = min(table["counter_bits"], WIRE_COUNTER_BITS)
    radius_m = min(table["wheel_radius_left_m"], table["wheel_radius_right_m"])
    readable_m_s = ((1 << (bits - 1)) * 2 * math.pi * radius_m / table["counts_per_rev"]
                    / (READABLE_PERIODS * ENCODER_PERIOD_US * 1e-6))
    cures = "fewer counts_per_rev, larger wheels" + (
        " or 32-bit counters" if table["counter_bits"] < WIRE_COUNTER_BITS else "")
    raise ProfileError(
        f"{source}: {table['counts_per_rev']} counts per turn of a {radius_m * 1e3:.4g} mm wheel "
        f"on {bits}-bit counters read wrapped above {readable_m_s:.3g} m/s (a step of "
        f"{READABLE_PERIODS} encoder periods), below the firmware's "
        f"{speed_mm_s / MM_PER_M:g} m/s bound ({cures}, or a lower max_wheel_speed_m_s)")


def _refuse_absurd_geometry(table: dict[str, Any], source: str) -> None:
    """The firmware's ``GEOMETRY_ABSURD``: one count of a wheel would turn the robot by 1/16 turn
    or more, so the board refuses the profile at boot (FAULT, CONFIG_INVALID) and never runs."""
    radius_m = max(table["wheel_radius_left_m"], table["wheel_radius_right_m"])
    turn_rad = 2 * math.pi * radius_m / table["counts_per_rev"] / table["wheelbase_m"]
    turn_deg = math.degrees(turn_rad)
    raise ProfileError(
        f"{source}: one count of a {radius_m * 1e3:.4g} mm wheel ({table['counts_per_rev']} counts "
        f"per turn) on a {table['wheelbase_m'] * 1e3:.4g} mm wheelbase turns the robot "
        f"{turn_deg:.3g} deg, the firmware refuses 1/16 turn (22.5 deg) or more (more "
        f"counts_per_rev, smaller wheels or a wider wheelbase)")
