"""The host's SecOC signer: an ODOM_AUTH after each ODOM_SET_POSE, ODOM_CONFIG, NAV_GOAL frame.

The host's own implementation of the profile the firmware verifies (``firmware.secoc``,
docs/secoc.md), with the ``cryptography`` package's AES-CMAC and the frames as the DBC draws them
(``ODOM_AUTH`` and ``ODOM_FRESHNESS`` from dbc/odocan.dbc):

    AUTHENTICATOR = first 32 bits of AES-128-CMAC(K, CAN ID u16 BE || 8 frame bytes || FV u48 BE)

FV (the freshness value) is ``EPOCH << 28 | COUNT`` (the widths of ``FV_EPOCH``/``FV_COUNT``);
ODOM_AUTH carries its low 16 bits (``FRESHNESS``). The signer learns the firmware's last accepted
FV from ODOM_FRESHNESS (``on_freshness``) and signs each command with the next value; it cannot
sign before it has seen one (the firmware sends it at boot, every second and after a refusal).

The key (``--secoc-key PATH``) is a file of exactly 16 raw bytes, or 32 hex digits (whitespace
around them allowed); anything else, or an unreadable file, is an ``OdocanError`` whose one-line
message names the path; a file that group or others may access is loaded with a warning. The key
is never printed, logged or put in an exception.
"""

from __future__ import annotations

import logging
import stat
import string
from pathlib import Path
from typing import Final

import cantools
import cantools.autosar
from cantools.database.can import Database, Message

from odocan.host.protocol.busfacts import ENC_COUNTER_MASK
from odocan.sim import contract
from odocan.sim.exceptions import OdocanError

KEY_BYTES: Final = 16  # AES-128
SECURED_MESSAGES: Final = ("NAV_GOAL", "ODOM_SET_POSE", "ODOM_CONFIG")  # ODOM_AUTH REQUEST VAL_s
FRESHNESS_WINDOW: Final = 4096  # the firmware accepts FV up to last + 4096 (docs/secoc.md)
log = logging.getLogger(__name__)


class SecocNotSynchronised(OdocanError):
    """No usable ODOM_FRESHNESS seen yet: the next freshness value is unknown."""


def load_secoc_key(path: str | Path) -> bytes:
    """The 16-byte AES-128 key in ``path`` (16 raw bytes, or 32 hex digits): a regular file,
    checked before it is read (a FIFO would block for ever); a key open to other users is
    taken with a warning, once it is known to be a key."""
    try:
        mode = Path(path).stat().st_mode
        if not stat.S_ISREG(mode):
            raise OdocanError(f"cannot read SecOC key {path}: not a regular file")
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise OdocanError(f"cannot read SecOC key {path}: {exc.strerror or exc}") from None
    key = _key_of(raw)
    if key is None:
        raise OdocanError(
            f"SecOC key {path}: {len(raw)} bytes, expected 16 raw bytes or 32 hex digits "
            "(AES-128)"
        )
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        log.warning(
            "SecOC key %s is open to other users (mode %03o): chmod 600 it",
            path,
            stat.S_IMODE(mode),
        )
    return key


def _key_of(raw: bytes) -> bytes | None:
    """The key in a key file's bytes (16 raw bytes, or 32 hex digits); None if neither."""
    if len(raw) == KEY_BYTES:
        return raw
    text = raw.strip()
    if len(text) == 2 * KEY_BYTES and all(chr(c) in string.hexdigits for c in text):
        return bytes.fromhex(text.decode("ascii"))
    return None


def secoc_messages(db: Database | None = None) -> tuple[Message, Message]:
    """``(ODOM_AUTH, ODOM_FRESHNESS)`` from ``db`` (default: the contract, dbc/odocan.dbc)."""
    source = db or contract.database()
    return source.get_message_by_name("ODOM_AUTH"), source.get_message_by_name("ODOM_FRESHNESS")


def _data_ids(message: Message) -> list[int]:
    attribute = message.dbc.attributes.get("E2EDataIDs") if message.dbc else None
    if attribute is None:
        raise OdocanError(f"{message.name} has no E2EDataIDs in the DBC")
    return [int(v) for v in str(attribute.value).split(",")]


class SecocSigner:
    """Signs secured command frames for one robot (one key, one freshness counter)."""

    def __init__(self, key: bytes, *, db: Database | None = None) -> None:
        if len(key) != KEY_BYTES:
            raise OdocanError(f"a SecOC key is {KEY_BYTES} bytes, not {len(key)}")
        self._key = key
        self._auth, self._fresh = secoc_messages(db)
        signals = {s.name: s for s in (*self._auth.signals, *self._fresh.signals)}
        self.mac_bits: int = signals["AUTHENTICATOR"].length
        self.freshness_bits: int = signals["FRESHNESS"].length
        self.count_bits: int = signals["FV_COUNT"].length
        self.epoch_bits: int = signals["FV_EPOCH"].length
        self._auth_ids = _data_ids(self._auth)
        self._fresh_ids = _data_ids(self._fresh)
        commands = db or contract.database()
        self._secured_ids = {
            commands.get_message_by_name(name).frame_id: request
            for request, name in enumerate(SECURED_MESSAGES)
        }
        self.next_fv: int | None = None
        self._counter = -1

    @property
    def auth_frame_id(self) -> int:
        """ODOM_AUTH's CAN ID (from the DBC)."""
        return int(self._auth.frame_id)

    @property
    def freshness_frame_id(self) -> int:
        """ODOM_FRESHNESS's CAN ID (from the DBC)."""
        return int(self._fresh.frame_id)

    def is_secured(self, can_id: int) -> bool:
        """True for the CAN IDs that need an ODOM_AUTH (ODOM_SET_POSE, ODOM_CONFIG, NAV_GOAL)."""
        return can_id in self._secured_ids

    def on_freshness(self, data: bytes) -> bool:
        """Adopt an ODOM_FRESHNESS frame's FV (next FV = it + 1); False: bad E2E, or FV 0."""
        if len(data) != 8 or not cantools.autosar.check_profile2_crc(
            data, self._fresh_ids[data[1] & ENC_COUNTER_MASK]
        ):
            return False
        fields = self._fresh.decode(data, decode_choices=False, scaling=False)
        assert isinstance(fields, dict)
        epoch, count = fields["FV_EPOCH"], fields["FV_COUNT"]
        assert isinstance(epoch, int) and isinstance(count, int)  # raw, no choices
        return self.adopt(epoch, count)

    def adopt(self, epoch: int, count: int) -> bool:
        """Adopt the firmware's last accepted FV (ODOM_FRESHNESS FV_EPOCH, FV_COUNT already
        E2E-checked); False, and no signing, when EPOCH is 0 (the firmware is unavailable)."""
        if epoch == 0:  # the firmware refuses every secured command (no key, NVM fault)
            self.next_fv = None
            return False
        self.next_fv = ((epoch << self.count_bits) | count) + 1
        return True

    def mac(self, can_id: int, pdu: bytes, fv: int) -> int:
        """The truncated authenticator (``mac_bits`` MSBs of the CMAC tag, as an integer)."""
        # cryptography only once a command is signed: a session without a key never loads it
        from cryptography.hazmat.primitives.ciphers import algorithms
        from cryptography.hazmat.primitives.cmac import CMAC

        cmac = CMAC(algorithms.AES(self._key))
        cmac.update(can_id.to_bytes(2, "big") + bytes(pdu) + fv.to_bytes(6, "big"))
        return int.from_bytes(cmac.finalize(), "big") >> (128 - self.mac_bits)

    def sign(self, can_id: int, pdu: bytes) -> bytes:
        """The ODOM_AUTH frame (8 bytes, E2E protected) for the command frame ``pdu``."""
        if can_id not in self._secured_ids:
            raise OdocanError(f"CAN ID 0x{can_id:03X} is not a secured command")
        if self.next_fv is None:
            raise SecocNotSynchronised("no ODOM_FRESHNESS from the firmware yet: cannot sign")
        fv = self.next_fv
        self._counter = (self._counter + 1) & ENC_COUNTER_MASK
        encoded = self._auth.encode(
            {
                "CHECKSUM": 0,
                "COUNTER": self._counter,
                "REQUEST": self._secured_ids[can_id],
                "FRESHNESS": fv & ((1 << self.freshness_bits) - 1),
                "AUTHENTICATOR": self.mac(can_id, pdu, fv),
            },
            scaling=False,
            strict=True,
        )
        data = cantools.autosar.apply_profile2_crc(bytes(encoded), self._auth_ids[self._counter])
        assert data is not None
        self.next_fv = self._successor(fv)
        return bytes(data)

    def _successor(self, fv: int) -> int:
        """FV + 1, or the next EPOCH's first value once the firmware rolls over (firmware.secoc)."""
        count_max = (1 << self.count_bits) - 1
        if (fv & count_max) > count_max - FRESHNESS_WINDOW:
            return (((fv >> self.count_bits) + 1) << self.count_bits) + 1
        return fv + 1

    def secure(self, frames: list[tuple[int, bytes]]) -> list[tuple[int, bytes]]:
        """``frames`` with an ODOM_AUTH after each secured one (others pass unchanged)."""
        out: list[tuple[int, bytes]] = []
        for can_id, data in frames:
            out.append((can_id, data))
            if can_id in self._secured_ids:
                out.append((self._auth.frame_id, self.sign(can_id, data)))
        return out
