"""The width sanitizer (tests/width_sanitizer.py): it can fail, it follows its stated rule, it
leaves the session's modules alone, and over the standard drives the firmware has zero sites."""

from __future__ import annotations

import ast
import sys
from typing import Any

import pytest

from odocan.firmware import fixmath, frames, odometry, trig
from odocan.firmware.frames import AckResult
from tests import width_sanitizer as ws

DRIVE_S = 6.0  # simulated seconds per lockstep drive (the rule does not depend on it)


def _run(source: str, call: str, *args: Any, exempt: frozenset[str] = frozenset()) -> ws.Recorder:
    """Instrument ``source`` as the loader does, run ``call(*args)`` in it, return the sites."""
    recorder = ws.Recorder()
    namespace: dict[str, Any] = {ws.CHECK_NAME: recorder.binop, ws.NEG_NAME: recorder.neg}
    exec(compile(ws.instrument(source, "planted.py", exempt), "planted.py", "exec"), namespace)
    namespace[call](*args)
    return recorder


def _only_site(recorder: ws.Recorder) -> ws.Site:
    sites = recorder.report()
    assert len(sites) == 1, [str(s) for s in sites]
    return sites[0]


# --- it can fail ---------------------------------------------------------------------------------


def test_a_planted_65_bit_product_is_caught_with_its_line_and_width() -> None:
    source = "def f(a, b):\n    x = a + 1\n    return x * b\n"
    site = _only_site(_run(source, "f", (1 << 32) - 1, 1 << 33))  # 2^32 * 2^33 = 2^65
    assert (site.path, site.line, site.op, site.what) == ("planted.py", 3, "*", "result")
    assert site.min_bits == site.max_bits == 66
    assert str(site) == "planted.py:3:11: '*' result 66 bits (1x)"
    site = _only_site(_run(source, "f", (1 << 32) - 1, 1 << 32))  # exactly 2^64: a u65
    assert site.max_bits == 65


def test_a_planted_wide_product_in_the_real_loader_is_caught(
    tmp_path: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The same through ``instrumented_firmware``: a firmware module with a planted product."""
    package = tmp_path / "odocan" / "firmware"
    package.mkdir(parents=True)
    (tmp_path / "odocan" / "__init__.py").write_text("")
    (package / "__init__.py").write_text("")
    (package / "planted.py").write_text("def f(a):\n    return a * a\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    recorder = ws.Recorder()
    with ws.instrumented_firmware(recorder):
        from odocan.firmware import planted  # type: ignore[attr-defined]

        assert planted.f((1 << 32) + 1) == ((1 << 32) + 1) ** 2
        assert planted.f(1 << 31) == 1 << 62
    site = _only_site(recorder)
    assert (site.path, site.line, site.max_bits, site.hits) == ("firmware/planted.py", 2, 65, 1)
    assert "odocan.firmware.planted" not in sys.modules


# --- the rule, exactly as the module docstring states it -----------------------------------------


@pytest.mark.parametrize(
    ("expression", "values", "flagged"),
    [
        ("a * b", (-(1 << 31), 1 << 32), False),  # -2^63: i64
        ("a * b", ((1 << 32) - 1, (1 << 32) + 1), False),  # 2^64 - 1: u64
        ("a * b", (-(1 << 32), (1 << 31) + 1), True),  # below -2^63
        ("a << b", (1, 64), True),
        ("a ** b", (2, 64), True),
        ("a + b", ((1 << 64) - 1, (1 << 64) - 1), False),  # a u64 carry
        ("a - b", (0, (1 << 64) - 1), False),  # a u64 borrow
        ("(a + b) >> 64", ((1 << 64) - 1, 1), False),  # the carry, read
        ("(a + b) * 1", ((1 << 64) - 1, 1), True),  # the carry, used as a number
        ("(a + b) + 1", ((1 << 64) - 1, 1), True),  # two carries are 66 bits
        ("-a", (-(1 << 63), 0), False),  # 2^63 fits u64 (C: 0u - x)
        ("a // b", (1 << 70, 3), True),  # an operand of 71 bits from outside: the result
        ("a & b", (1 << 70, 1), False),  # masks and comparisons are not checked
    ],
)
def test_the_rule(expression: str, values: tuple[int, int], flagged: bool) -> None:
    source = f"def f(a, b):\n    return {expression}\n"
    assert bool(_run(source, "f", *values).sites) is flagged


def test_augmented_assignments_are_checked() -> None:
    source = "def f(a, b):\n    x = a\n    x *= b\n    x += 1\n    return x\n"
    site = _only_site(_run(source, "f", 1 << 40, 1 << 40))
    assert (site.line, site.op) == (3, "*")


def test_a_wide_value_is_reported_once_where_it_is_made() -> None:
    source = "def f(a, b):\n    return (a * b + 1) >> 64\n"
    assert _only_site(_run(source, "f", 1 << 40, 1 << 40)).op == "*"


def test_only_helpers_that_give_their_c_form_are_exempt() -> None:
    source = (
        "def audited(a, b):\n"
        '    """The product.\n\n    C: ``smul_128(a, b, &hi, &lo)``.\n    """\n'
        "    return a * b\n\n"
        "def unaudited(a, b):\n"
        '    """The product, in C somehow."""\n'
        "    return a * b\n"
    )
    exempt = ws.audited_helpers(ast.parse(source))
    assert exempt == {"audited"}
    assert not _run(source, "audited", 1 << 40, 1 << 40, exempt=exempt).sites
    assert _run(source, "unaudited", 1 << 40, 1 << 40, exempt=exempt).sites


def test_the_audited_fixmath_helpers_are_the_reviewed_set() -> None:
    """A helper becomes exempt by a ``C:`` line: adding one is a reviewed change of this list."""
    source = ws.FIRMWARE_DIR.joinpath("fixmath.py").read_text(encoding="utf-8")
    assert ws.audited_helpers(ast.parse(source)) == {
        "wrap_u16",
        "wrap_u32",
        "wrap_i16",
        "wrap_i32",
        "wrap_i64",
        "wrap_signed",
        "mul_sub_wrap_i64",
        "mul_shr_i64",
        "mul_round_i64",
        "mul_add_hi_i64",
        "mul_sat_i64",
        "mul_shr_round_i64",
        "div_q62_i128",
        "muldiv_round_u64",
    }


# --- the firmware --------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def drives() -> tuple[ws.Recorder, ws.DriveLog]:
    recorder = ws.Recorder()
    log = ws.standard_drives(recorder, DRIVE_S)
    return recorder, log


def test_the_firmware_has_zero_wide_sites(drives: tuple[ws.Recorder, ws.DriveLog]) -> None:
    recorder, _ = drives
    sites = "\n".join(str(site) for site in recorder.report())
    assert not recorder.sites, f"{len(recorder.sites)} wide site(s):\n{sites}"


def test_the_drives_reach_every_arithmetic_place_of_the_firmware(
    drives: tuple[ws.Recorder, ws.DriveLog],
) -> None:
    recorder, _ = drives
    places = ws.firmware_sites()
    missed = sorted(p for p in places if (p.path, p.line, p.col) not in recorder.seen)
    assert len(places) > 250
    assert recorder.checks > 500_000
    assert not missed, "\n".join(f"{p.path}:{p.line}:{p.col} in {p.function}" for p in missed)


def test_the_drives_did_what_they_say(drives: tuple[ws.Recorder, ws.DriveLog]) -> None:
    _, log = drives
    for frame_id in (frames.ODOM_POSE_X_ID, frames.NAV_STATUS_ID, frames.ODOM_STATUS_ID):
        assert log.heard.get(frame_id, 0) > 100
    answered = {(ack.request_id, ack.request_field, ack.result) for ack in log.acks}
    assert (frames.NAV_GOAL_ID, frames.NavGoalField.GO, AckResult.ACK) in answered
    assert (frames.ODOM_CONFIG_ID, frames.ConfigParam.APPLY, AckResult.ACK) in answered
    assert (frames.ODOM_CONFIG_ID, frames.ConfigParam.APPLY, AckResult.NACK) in answered
    assert (frames.ODOM_SET_POSE_ID, frames.SetPoseField.APPLY, AckResult.ACK) in answered
    reasons = {ack.reason for ack in log.acks}  # the secured rig: every SecOC verdict
    assert {int(r) for r in frames.AckReason if r.name.startswith("AUTH_")} <= reasons
    assert log.heard.get(frames.ODOM_FRESHNESS_ID, 0) >= 4  # boot x3, refusal, periodic


def test_the_session_keeps_its_own_modules(drives: tuple[ws.Recorder, ws.DriveLog]) -> None:
    """After the drives, every odocan module is the one imported before, uninstrumented."""
    assert sys.modules["odocan.firmware.trig"] is trig
    assert sys.modules["odocan.firmware.odometry"] is odometry
    assert sys.modules["odocan.firmware"].fixmath is fixmath
    for module in (trig, odometry, fixmath):
        assert ws.CHECK_NAME not in vars(module)
    assert vars(odometry)["sincos_q30"] is trig.sincos_q30
