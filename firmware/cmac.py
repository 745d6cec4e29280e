"""AES-CMAC (RFC 4493, NIST SP 800-38B) over AES-128, integer-only: the SecOC authenticator.

Blocks are four big-endian u32 words, as in ``firmware.aes``. ``CmacKey`` holds what is derived
once per key at provisioning time (C: ``typedef struct { uint32_t rk[44], k1[4], k2[4]; }``):
the AES round keys and the two subkeys of RFC 4493 2.3,

    L  = AES-128(K, 0^128)
    K1 = L << 1,  XOR 0x87 into the last byte if the MSB of L was 1
    K2 = K1 << 1, likewise,

so a MAC over ``n`` blocks costs exactly ``n`` block encryptions (RFC 4493 2.4): CBC-MAC with
the last block XORed with K1 when it is complete, or padded with ``10...0`` and XORed with K2.
SecOC's authenticator input is exactly one block (``firmware.secoc``): one AES per command.
"""

from __future__ import annotations

from typing import Final, NamedTuple

from odocan.firmware.aes import (
    AES_BLOCK_BYTES,
    encrypt_words,
    expand_key,
    load_be32,
    store_be32,
)
from odocan.firmware.fixmath import U32_MAX, u32

CMAC_RB_128: Final = 0x87  # R_128 of SP 800-38B 5.3: x^128 = x^7 + x^2 + x + 1
PAD_FIRST_BYTE: Final = 0x80  # the "1" bit of RFC 4493's padding 10^i


class CmacKey(NamedTuple):
    """A provisioned AES-CMAC key: round keys (44 u32) and subkeys K1, K2 (4 u32 each)."""

    rk: tuple[u32, ...]
    k1: tuple[u32, ...]
    k2: tuple[u32, ...]


def _shift_left_1(block: tuple[u32, ...]) -> tuple[u32, ...]:
    """RFC 4493 2.3: the 128-bit ``block`` shifted left by one, XOR Rb if its MSB was set."""
    w0, w1, w2, w3 = block
    carry_out = w0 >> 31
    w0 = ((w0 << 1) | (w1 >> 31)) & U32_MAX
    w1 = ((w1 << 1) | (w2 >> 31)) & U32_MAX
    w2 = ((w2 << 1) | (w3 >> 31)) & U32_MAX
    w3 = (w3 << 1) & U32_MAX
    if carry_out:  # C: w3 ^= CMAC_RB_128 & -(uint32_t)carry_out (no branch on the key)
        w3 ^= CMAC_RB_128
    return (w0, w1, w2, w3)


def cmac_key(key: bytes | bytearray) -> CmacKey:
    """Provision a 16-byte key: expand it and derive K1, K2 (RFC 4493 Generate_Subkey).

    Precondition: ``len(key) == 16`` (``firmware.secoc.provision`` checks it).
    """
    rk = expand_key(key)
    ell = encrypt_words(rk, 0, 0, 0, 0)
    k1 = _shift_left_1(ell)
    return CmacKey(rk, k1, _shift_left_1(k1))


def cmac(key: CmacKey, message: bytes | bytearray) -> bytes:
    """The 16-byte AES-CMAC tag of ``message`` (any length, 0 included): RFC 4493 2.4.

    C: ``void aes_cmac(const cmac_key_t *key, const uint8_t *msg, uint32_t len,
    uint8_t tag[16])``; the chaining value ``x0..x3`` is four u32.
    """
    length = len(message)
    full_blocks = (length + AES_BLOCK_BYTES - 1) >> 4  # n = ceil(len / 16)
    if full_blocks == 0:
        full_blocks = 1
    last_complete = length != 0 and length & (AES_BLOCK_BYTES - 1) == 0
    x0 = x1 = x2 = x3 = 0
    offset = 0
    for _ in range(full_blocks - 1):
        x0, x1, x2, x3 = encrypt_words(
            key.rk,
            x0 ^ load_be32(message, offset),
            x1 ^ load_be32(message, offset + 4),
            x2 ^ load_be32(message, offset + 8),
            x3 ^ load_be32(message, offset + 12),
        )
        offset += AES_BLOCK_BYTES
    last = _last_block(message, offset, last_complete)
    sub = key.k1 if last_complete else key.k2
    tag = encrypt_words(
        key.rk,
        x0 ^ sub[0] ^ load_be32(last, 0),
        x1 ^ sub[1] ^ load_be32(last, 4),
        x2 ^ sub[2] ^ load_be32(last, 8),
        x3 ^ sub[3] ^ load_be32(last, 12),
    )
    out = bytearray(AES_BLOCK_BYTES)
    for i in range(4):
        store_be32(out, 4 * i, tag[i])
    return bytes(out)


def _last_block(message: bytes | bytearray, offset: int, complete: bool) -> bytearray:
    """The last block ``M_n``: copied as is when complete, else padded ``10...0`` (a u8[16])."""
    block = bytearray(AES_BLOCK_BYTES)
    tail = len(message) - offset
    for i in range(tail):
        block[i] = message[offset + i]
    if not complete:
        block[tail] = PAD_FIRST_BYTE
    return block
