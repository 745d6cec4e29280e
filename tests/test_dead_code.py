"""No firmware code without a caller in the product, unless it says why (issue 17).

vulture reads the product (firmware/, sim/, host/, tools/; not tests/, which is not a caller that
counts: a function only tests call is a test helper, and test helpers do not belong in the MCU)
and lists every firmware name nothing there uses. Each must be in ``JUSTIFIED`` with its reason;
an entry that has gained a caller or is gone fails too, so the list only shrinks.

The C port the same way: every external function defined in firmware/c/*.c is called from another
firmware C file or exported by the shared-library ABI (odocan_fw.h), or is in ``JUSTIFIED_C``.
The test programs (probe.c, vectors_check.c, bench_odometry.c) are not callers that count, and
dbc/odocan.c is cantools' generated codec, kept whole.
"""

from __future__ import annotations

import re
from pathlib import Path

import vulture

ROOT = Path(__file__).resolve().parents[1]
PRODUCT = ("firmware", "sim", "host", "tools")

_ACK = "an AckReason value, reached as AckReason(int(AuthStatus))"
_C_TWIN = "mirrored by the C port, whose probe proves the two equal; goes with its C twin"
JUSTIFIED: dict[str, str] = {
    "firmware/config.py:RK2": "an Integrator value, reached by value from the DBC and ODOM_CONFIG",
    "firmware/frames.py:AUTH_FAILED": _ACK,
    "firmware/frames.py:AUTH_FRESHNESS": _ACK,
    "firmware/frames.py:AUTH_MISSING": _ACK,
    "firmware/frames.py:AUTH_UNAVAILABLE": _ACK,
    "firmware/e2e.py:lost_data": "AUTOSAR E2E_P02 receiver state (LostData), kept as the spec "
    "names it and as e2e.c keeps it",
    "firmware/e2e.py:CRC8H2F_CHECK": "the CRC's AUTOSAR check value, next to the CRC it checks",
    "firmware/e2e.py:crc8h2f": f"the bare CRC-8H2F (the ECU seals with p02_crc); {_C_TWIN}",
    "firmware/frames.py:unpack_wheel_encoders": "WHEEL_ENCODERS as a record (fields by name, "
    "as every other unpack_*): the ECU reads the same fields as a plain tuple each frame "
    f"(unpack_wheel_encoders_fields, ~0.3 us less); {_C_TWIN}",
    "firmware/e2e.py:new_period": "one receive period, as AUTOSAR calls it and as e2e.c's "
    "e2e_new_period (ecu.c's loop); the Python ECU widens by new_periods, one saturating add",
}


def firmware_without_product_caller() -> set[str]:
    """``path:name`` of every firmware name vulture finds unused in the product."""
    scan = vulture.Vulture()
    scan.scavenge([str(ROOT / room) for room in PRODUCT])
    unused = set()
    for item in scan.get_unused_code():
        path = Path(item.filename).resolve().relative_to(ROOT).as_posix()
        if path.startswith("firmware/"):
            unused.add(f"{path}:{item.name}")
    return unused


def test_every_firmware_name_without_a_product_caller_is_justified() -> None:
    unjustified = firmware_without_product_caller() - set(JUSTIFIED)
    assert not unjustified, f"remove these, give them a caller, or justify them: {unjustified}"


def test_the_justified_list_holds_only_names_still_without_a_caller() -> None:
    """Also proves the scan reads the firmware: an empty scan would leave every entry stale."""
    stale = set(JUSTIFIED) - firmware_without_product_caller()
    assert not stale, f"take these off JUSTIFIED (they have a caller now, or are gone): {stale}"


# --- the C port ---------------------------------------------------------------------------------
C_DIR = ROOT / "firmware" / "c"
C_TEST_PROGRAMS = ("probe.c", "vectors_check.c", "bench_odometry.c")
JUSTIFIED_C: dict[str, str] = {
    "crc8h2f": "the bare CRC-8H2F with its AUTOSAR check values, e2e.py's twin (the ECU seals with "
    "p02_crc)",
    "aes_cmac": "cmac.py's twin, which the product calls (sim/provision.py, the host's signer); "
    "the probe proves the two equal",
    "sin_q30": "trig.py's sin_q30, cos_q30's pair (the ECU calls sincos_q30 and cos_q30)",
    "ecu_tick": "a HAL entry point (ecu.h, firmware/c/README.md) for a board without a timer; "
    "the ABI's boards use ecu_tick_at",
}
_COMMENT = re.compile(r"/\*.*?\*/|//[^\n]*", re.S)
_EXTERN_DEF = re.compile(r"^(?!static\b)[A-Za-z_][\w \t*]*?\b(\w+)\([^;{}]*\)\s*\{", re.M)


def _c_code(path: Path) -> str:
    """A C file's text without its comments."""
    return _COMMENT.sub(" ", path.read_text(encoding="utf-8"))


def c_firmware_without_caller() -> set[str]:
    """Every external function of the hand-written C firmware that no other firmware C file
    calls (its own file counts: a call besides the definition) and the ABI does not export."""
    sources = [p for p in sorted(C_DIR.glob("*.c")) if p.name not in C_TEST_PROGRAMS]
    code = {p.name: _c_code(p) for p in sources}
    abi = _c_code(C_DIR / "odocan_fw.h")
    unused = set()
    for text in code.values():
        for name in _EXTERN_DEF.findall(text):
            uses = sum(len(re.findall(rf"\b{name}\b", other)) for other in code.values())
            if uses <= 1 and not re.search(rf"\b{name}\b", abi):
                unused.add(name)
    return unused


def test_the_c_scan_reads_the_port() -> None:
    """The scan finds every external definition of a file, static ones excepted."""
    defined = set(_EXTERN_DEF.findall(_c_code(C_DIR / "e2e.c")))
    assert {"p02_crc", "e2e_check", "crc8h2f"} <= defined
    assert not defined & {"p02_protect", "p02_next_counter"}  # gone to the probe / the tests


def test_every_c_function_without_a_caller_is_justified() -> None:
    unjustified = c_firmware_without_caller() - set(JUSTIFIED_C)
    assert not unjustified, f"remove these, give them a caller, or justify them: {unjustified}"


def test_the_justified_c_list_holds_only_functions_still_without_a_caller() -> None:
    stale = set(JUSTIFIED_C) - c_firmware_without_caller()
    assert not stale, f"take these off JUSTIFIED_C (they have a caller now, or are gone): {stale}"
