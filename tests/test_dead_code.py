"""No firmware code without a caller in the product, unless it says why (issue 17).

vulture reads the product (firmware/, sim/, host/, tools/; not tests/, which is not a caller that
counts: a function only tests call is a test helper, and test helpers do not belong in the MCU)
and lists every firmware name nothing there uses. Each must be in ``JUSTIFIED`` with its reason;
an entry that has gained a caller or is gone fails too, so the list only shrinks.
"""

from __future__ import annotations

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
    "firmware/e2e.py:lost_data": "AUTOSAR E2E_P02 receiver state (LostData), kept as the spec "
    "names it and as e2e.c keeps it",
    "firmware/e2e.py:CRC8H2F_CHECK": "the CRC's AUTOSAR check value, next to the CRC it checks",
    "firmware/e2e.py:crc8h2f": f"the bare CRC-8H2F (the ECU seals with p02_crc); {_C_TWIN}",
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
