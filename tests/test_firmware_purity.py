"""firmware/ is integer-only and standard-library-only: an AST walk of every module proves it."""

from __future__ import annotations

import pytest

from tests.firmware_purity import FIRMWARE_DIR, scan_firmware, scan_source


def test_every_firmware_module_is_integer_only_and_stdlib_only() -> None:
    modules = sorted(FIRMWARE_DIR.rglob("*.py"))
    assert len(modules) >= 4, "the scan must see the firmware modules"
    violations = scan_firmware()
    assert violations == [], "\n".join(map(str, violations))


@pytest.mark.parametrize(
    ("source", "what"),
    [
        ("x = 1.5\n", "float literal"),
        ("x = 1e3\n", "float literal"),
        ("x = 3 / 2\n", "true division"),
        ("x = 3\nx /= 2\n", "true division"),
        ("x = float(3)\n", "float()"),
        ("x = round(3)\n", "round()"),
        ("x = 2 ** -1\n", "negative exponent"),
        ("import math\n", "'math'"),
        ("from numpy import array\n", "'numpy'"),
        ("import can\n", "'can'"),
        ("from odocan.sim.vehicle import Vehicle\n", "'odocan.sim.vehicle'"),
        ("import firmware.fixmath\n", "'firmware.fixmath'"),
        ("from host import cli\n", "'host'"),
        ("import decimal\n", "'decimal'"),
    ],
)
def test_the_scan_catches_each_forbidden_construct(source: str, what: str) -> None:
    violations = scan_source(source)
    assert len(violations) == 1
    assert what in violations[0].what


def test_the_scan_allows_integer_code() -> None:
    source = (
        "from __future__ import annotations\nimport struct\n"
        "from odocan.firmware.fixmath import wrap_u32\n"
        "x = (7 // 2) << 3 >> 1\ny = 2 ** 10\nz = divmod(7, 2)\n"
    )
    assert scan_source(source) == []
