"""SecOC-style authenticated commands: ODOM_AUTH follows each ODOM_SET_POSE, ODOM_CONFIG, NAV_GOAL.

The profile (docs/secoc.md has the reasoning, dbc/odocan.dbc the frames)::

    authenticator = MSB_32( AES-128-CMAC(K, DataID || PDU || FV) )

* ``DataID`` (u16, big-endian): the secured message's CAN ID (0x280, 0x300, 0x301), so an
  authenticator for one message never verifies another.
* ``PDU``: the 8 bytes of the command frame exactly as received (E2E header included).
* ``FV`` (u48, big-endian): the complete freshness value, ``EPOCH (u20) << 28 | COUNT (u28)``.

2 + 8 + 6 = 16 bytes: exactly one AES block, so one verification costs one AES-128 encryption
(the CMAC subkey K1 is derived once when the key is provisioned). ``MAC_BITS = 32``: a forgery
succeeds with probability 2^-32 per try. ODOM_AUTH carries ``REQUEST`` (which message),
``FRESHNESS`` (the low 16 bits of FV) and ``AUTHENTICATOR`` (u32).

**Freshness** (the receiver's rules; the sender only has to count up):

* the receiver keeps ``last_fv``, the last accepted FV, and rebuilds the complete FV of a frame
  as ``last_fv + delta`` with ``delta = (FRESHNESS - last_fv) mod 2^16``; it accepts only
  ``1 <= delta <= FRESHNESS_WINDOW`` (strictly greater, at most 4096 ahead), and only when the
  rebuilt FV's EPOCH is the current one; then the authenticator must match. Nothing changes on
  a refusal: ``last_fv`` moves only when a whole command verified.
* **Reboot**: ``EPOCH`` lives in non-volatile memory (``FreshnessNvm``, the HAL's NVM cell). At
  boot the firmware reads it, adds one, and writes it back *before* accepting anything; then
  ``last_fv = EPOCH << 28``. Every FV accepted before the reboot had a smaller EPOCH, so it is
  below ``last_fv`` forever: a reboot never reopens an old value, and the NVM is written once per
  boot (and once per 2^28 - 4096 commands), not once per command.
* **Resynchronisation**: the firmware sends ODOM_FRESHNESS (its ``last_fv``, unauthenticated:
  freshness is not secret) at boot, every second, after every FRESHNESS refusal and after an
  EPOCH rollover. The host signs its next command with ``last_fv + 1``. A forged ODOM_FRESHNESS
  can only make the host sign values the firmware refuses (a denial of service, which a node on
  the bus can cause anyway); it can never make the firmware accept anything.
* **Fail closed**: no valid key, an NVM write that failed, or EPOCH exhausted (2^20 boots) ->
  every secured command is refused (``UNAVAILABLE``).

All integer-only; per command: one AES block, no allocation but the 16-byte input block (a
``uint8_t[16]`` on the stack in C). The frame codecs live in ``firmware.frames``;
the AUTH reasons are ``firmware.frames.AckReason``'s AUTH_*.
"""

from __future__ import annotations

from enum import IntEnum
from typing import Final, NamedTuple

from odocan.firmware import frames as fr
from odocan.firmware.aes import AES128_KEY_BYTES, AES_BLOCK_BYTES, encrypt_words, load_be32
from odocan.firmware.cmac import CmacKey, cmac_key
from odocan.firmware.errors import ErrorMask
from odocan.firmware.fixmath import U32_MAX, u16, u32, u64, wrap_u32
from odocan.firmware.frames import NAV_GOAL_ID, ODOM_CONFIG_ID, ODOM_SET_POSE_ID
from odocan.firmware.hal import FreshnessNvm

# --- the profile ---
MAC_BITS: Final = 32  # truncated authenticator on the wire
FRESHNESS_TX_BITS: Final = 16  # truncated freshness on the wire
FRESHNESS_TX_MASK: Final = (1 << FRESHNESS_TX_BITS) - 1
COUNT_BITS: Final = 28  # FV = EPOCH << 28 | COUNT: 48 bits, firmware.frames.FV_MASK
EPOCH_BITS: Final = 20
COUNT_MASK: Final = (1 << COUNT_BITS) - 1
EPOCH_MAX: Final = (1 << EPOCH_BITS) - 1
FRESHNESS_WINDOW: Final = 4096  # accepted: 1 <= FV - last_fv <= 4096
ROLLOVER_COUNT: Final = COUNT_MASK - FRESHNESS_WINDOW  # past it, EPOCH advances
AUTH_TIMEOUT_TICKS: Final = 2  # a held command waits <= 2 ticks (20 ms) for its ODOM_AUTH
FRESHNESS_PERIOD_TICKS: Final = 100  # ODOM_FRESHNESS every 1 s

# --- the frames (dbc/odocan.dbc; codecs in firmware.frames) ---
ODOM_AUTH_ID: Final = fr.ODOM_AUTH_ID
ODOM_FRESHNESS_ID: Final = fr.ODOM_FRESHNESS_ID
ODOM_AUTH_DATA_IDS: Final = fr.ODOM_AUTH_DATA_IDS
ODOM_FRESHNESS_DATA_IDS: Final = fr.ODOM_FRESHNESS_DATA_IDS
FRAME_LEN: Final = 8
OdomAuth = fr.OdomAuth
unpack_odom_auth = fr.unpack_odom_auth


class AuthRequest(IntEnum):
    """ODOM_AUTH ``REQUEST``: the secured message authenticated (one held slot each)."""

    NAV_GOAL = 0
    ODOM_SET_POSE = 1
    ODOM_CONFIG = 2


# The secured messages' CAN IDs (their SecOC DataIDs), indexed by AuthRequest.
SECURED_IDS: Final[tuple[int, ...]] = (NAV_GOAL_ID, ODOM_SET_POSE_ID, ODOM_CONFIG_ID)


class AuthStatus(IntEnum):
    """Result of one verification; the values are ODOM_ACK ``REASON``'s AUTH_* codes."""

    OK = 0
    FAILED = 7  # AUTH_FAILED: the authenticator does not match (forged, corrupted, wrong key)
    FRESHNESS = 8  # AUTH_FRESHNESS: FV not strictly greater or beyond the window (a replay)
    MISSING = 9  # AUTH_MISSING: no ODOM_AUTH within AUTH_TIMEOUT_TICKS, or displaced by another
    UNAVAILABLE = 10  # AUTH_UNAVAILABLE: no valid key, NVM write failed, EPOCH exhausted


class FreshnessCause(IntEnum):
    """ODOM_FRESHNESS ``CAUSE``: why it was sent."""

    BOOT = 0
    PERIODIC = 1
    REFUSED = 2  # right after a FRESHNESS refusal
    ROLLOVER = 3  # EPOCH advanced after 2^28 - 4096 commands
    UNAVAILABLE = 4  # secured commands are refused (see AuthStatus.UNAVAILABLE)


def authenticator_input(data_id: u16, pdu: bytes | bytearray, fv: u64) -> bytearray:
    """The 16-byte DataToAuthenticator: DataID (u16 BE) || PDU (8 bytes) || FV (u48 BE)."""
    block = bytearray(AES_BLOCK_BYTES)
    block[0] = (data_id >> 8) & 0xFF
    block[1] = data_id & 0xFF
    for i in range(FRAME_LEN):
        block[2 + i] = pdu[i]
    for i in range(6):
        block[10 + i] = (fv >> (40 - 8 * i)) & 0xFF
    return block


def authenticator(key: CmacKey, data_id: u16, pdu: bytes | bytearray, fv: u64) -> u32:
    """MSB_32 of AES-CMAC over one complete block: ``AES(K, M XOR K1)``, the first 4 bytes BE."""
    block = authenticator_input(data_id, pdu, fv)
    k1 = key.k1
    tag = encrypt_words(
        key.rk,
        load_be32(block, 0) ^ k1[0],
        load_be32(block, 4) ^ k1[1],
        load_be32(block, 8) ^ k1[2],
        load_be32(block, 12) ^ k1[3],
    )
    return tag[0]


def truncate(mac32: u32, mac_bits: int) -> u32:
    """The first ``mac_bits`` (1..32) of a 32-bit authenticator, right-aligned."""
    return mac32 >> (MAC_BITS - mac_bits)


class SecocReceiver:
    """The freshness manager and verifier of the firmware (one key, one FV for all messages).

    ``mac_bits`` (default 32, the profile) compares only the first ``mac_bits`` of the
    authenticator, right-aligned in the frame: the bench uses 8..24 to measure that the forgery
    rate is 2^-mac_bits.
    """

    __slots__ = (
        "_key",
        "_nvm",
        "count_failed",
        "count_freshness",
        "count_ok",
        "epoch",
        "last_fv",
        "mac_bits",
        "sync_cause",
    )

    def __init__(self, key: bytes | bytearray, nvm: FreshnessNvm, *, mac_bits: int = MAC_BITS):
        self._nvm = nvm
        self.mac_bits = mac_bits
        self._key: CmacKey | None = cmac_key(key) if len(key) == AES128_KEY_BYTES else None
        self.epoch: u32 = 0
        self.last_fv: u64 = 0
        self.count_ok: u32 = 0
        self.count_failed: u32 = 0
        self.count_freshness: u32 = 0
        self.sync_cause: FreshnessCause | None = None  # an ODOM_FRESHNESS is due, and why
        self.boot()

    def boot(self) -> None:
        """Reset and power-on: EPOCH <- NVM + 1, written back before anything is accepted."""
        self._advance_epoch(self._nvm.read_epoch(), FreshnessCause.BOOT)

    def _advance_epoch(self, previous: u32, cause: FreshnessCause) -> None:
        """Take EPOCH ``previous + 1`` (persisted first), COUNT restarts at 0; else fail closed.

        ``previous`` is a u32 from NVM (an erased cell must read 0: the BSP maps it).
        """
        if self._key is None or previous >= EPOCH_MAX or not self._nvm.write_epoch(previous + 1):
            self.epoch = 0  # unavailable: every secured command is refused
            self.sync_cause = FreshnessCause.UNAVAILABLE
            return
        self.epoch = previous + 1
        self.last_fv = self.epoch << COUNT_BITS
        self.sync_cause = cause

    def verify(self, data_id: u16, pdu: bytes | bytearray, freshness: u16, mac: u32) -> AuthStatus:
        """Verify one secured PDU against its ODOM_AUTH fields; on OK, ``last_fv`` advances.

        Order: availability, freshness (cheap), then the authenticator (one AES block).
        """
        if self._key is None or self.epoch == 0:
            return AuthStatus.UNAVAILABLE
        delta = (freshness - self.last_fv) & FRESHNESS_TX_MASK  # C: (uint16_t)(fresh - last)
        fv = self.last_fv + delta  # u64: < 2^48 + 2^16
        if delta == 0 or delta > FRESHNESS_WINDOW or (fv >> COUNT_BITS) != self.epoch:
            self.count_freshness = wrap_u32(self.count_freshness + 1)
            self.sync_cause = FreshnessCause.REFUSED
            return AuthStatus.FRESHNESS
        expected = truncate(authenticator(self._key, data_id, pdu, fv), self.mac_bits)
        if (expected ^ (mac & U32_MAX)) != 0:  # C: a full-word compare, no early exit
            self.count_failed = wrap_u32(self.count_failed + 1)
            return AuthStatus.FAILED
        self.count_ok = wrap_u32(self.count_ok + 1)
        self.last_fv = fv
        if (fv & COUNT_MASK) > ROLLOVER_COUNT:
            self._advance_epoch(self.epoch, FreshnessCause.ROLLOVER)
        return AuthStatus.OK

    def take_sync_cause(self) -> FreshnessCause | None:
        """Why an ODOM_FRESHNESS is due now (boot, refusal, rollover, unavailable), once; else
        None. The ECU asks every tick (``firmware.auth``), and sends one with PERIODIC every
        ``FRESHNESS_PERIOD_TICKS`` besides."""
        cause = self.sync_cause
        self.sync_cause = None
        return cause

    def freshness_frame(self, counter: int, cause: FreshnessCause) -> bytes:
        """ODOM_FRESHNESS carrying ``last_fv`` (0 when unavailable) and ``cause``."""
        fv = self.last_fv if self.epoch else 0
        return pack_odom_freshness(counter, cause, fv)


class Held(NamedTuple):
    """A secured command frame waiting for its ODOM_AUTH."""

    can_id: int
    pdu: bytes
    tick: u32


class SecuredCommands:
    """One held slot per secured message: verify before acting.

    The ECU, after a secured frame passed its E2E check, calls ``hold`` instead of acting; when
    an ODOM_AUTH passed its own E2E check, ``authenticate`` returns the held frame with the
    verdict, and the ECU acts on it only when the verdict is OK (else it NACKs it with the
    verdict as REASON). ``expire`` (once per tick) hands back a frame whose ODOM_AUTH did not come
    within ``AUTH_TIMEOUT_TICKS``: NACK AUTH_MISSING. Fixed storage: three slots.
    """

    __slots__ = ("_slots", "orphans", "receiver")

    def __init__(self, receiver: SecocReceiver) -> None:
        self.receiver = receiver
        self._slots: list[Held | None] = [None, None, None]
        self.orphans: u32 = 0  # ODOM_AUTH frames with no held command (u32, wrapping)

    def hold(self, request: AuthRequest, pdu: bytes, tick: u32) -> Held | None:
        """Hold a secured frame; returns the frame it displaced (to NACK AUTH_MISSING), if any."""
        displaced = self._slots[request]
        self._slots[request] = Held(SECURED_IDS[request], pdu, tick)
        return displaced

    def authenticate(self, auth: OdomAuth) -> tuple[AuthStatus, Held] | None:
        """Verify the held frame ``auth`` is for; None (counted) when nothing is held for it."""
        held = self._slots[auth.request] if auth.request < len(SECURED_IDS) else None
        if held is None:
            self.orphans = wrap_u32(self.orphans + 1)
            return None
        self._slots[auth.request] = None
        status = self.receiver.verify(held.can_id, held.pdu, auth.freshness, auth.authenticator)
        return status, held

    def expire(self, tick: u32) -> Held | None:
        """One held frame older than ``AUTH_TIMEOUT_TICKS`` (removed), or None; call until None."""
        for index, held in enumerate(self._slots):
            if held is not None and wrap_u32(tick - held.tick) > AUTH_TIMEOUT_TICKS:
                self._slots[index] = None
                return held
        return None


# --- frame codec: firmware.frames (a host's ODOM_AUTH packer: tests/host_frames.py) ---
def pack_odom_freshness(counter: int, cause: int, fv: u64) -> bytes:
    """ODOM_FRESHNESS (``firmware.frames.pack_odom_freshness``)."""
    return fr.pack_odom_freshness(counter, cause, fv, ErrorMask())
