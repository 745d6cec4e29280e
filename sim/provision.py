"""SecOC key provisioning for a fleet: each robot's own key, derived from the fleet key.

``odocan fleet --secoc-key PATH`` gives one 16-byte *fleet* key; every robot's firmware is
provisioned with its own key derived from it, and its bridge signs with that same derived key:

```
K_robot = AES-128-CMAC(K_fleet, 0x01 || "odocan-secoc" || 0x00 || name || 0x0080)
```

NIST SP 800-108r1 4.1 (KDF in counter mode, PRF = CMAC): counter ``[i]_8`` = 1, Label
``odocan-secoc``, a zero byte, Context = the robot's name in ASCII (``robot001``), and ``[L]_16``
= 128, the derived key's length in bits; one PRF block is the whole key.

Why not one key in every robot: a key is provisioned into the MCU's flash, and a robot is the
part of the fleet an attacker can carry away. With per-robot keys, a key read out of one robot
authenticates commands to that robot only; the fleet key never leaves the provisioning station
and the bridges (which hold every robot's command rights anyway). It is the key diversification
AUTOSAR deployments use per ECU, and it costs one CMAC per robot at start.

``firmware.cmac`` computes it here (integer-only, proven against ``cryptography`` and RFC 4493);
``tests/test_fleet_secoc.py`` checks it against ``cryptography``'s CMAC.
"""

from __future__ import annotations

from typing import Final

from odocan.firmware.cmac import cmac, cmac_key

KEY_BYTES: Final = 16
KDF_LABEL: Final = b"odocan-secoc"
KDF_COUNTER: Final = b"\x01"
KDF_LENGTH_BITS: Final = (8 * KEY_BYTES).to_bytes(2, "big")


def kdf_input(name: str) -> bytes:
    """SP 800-108's fixed input for robot ``name``: counter, Label, 0x00, Context, [L]_16."""
    return KDF_COUNTER + KDF_LABEL + b"\x00" + name.encode("ascii") + KDF_LENGTH_BITS


def robot_key(fleet_key: bytes, name: str) -> bytes:
    """Robot ``name``'s 16-byte SecOC key, derived from the 16-byte ``fleet_key``."""
    if len(fleet_key) != KEY_BYTES:
        raise ValueError(f"a SecOC fleet key is {KEY_BYTES} bytes, not {len(fleet_key)}")
    return cmac(cmac_key(fleet_key), kdf_input(name))
