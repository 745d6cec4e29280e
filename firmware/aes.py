"""AES-128 block encryption (FIPS-197), integer-only: the cipher under the SecOC authenticator.

Only the forward cipher is needed (CMAC never decrypts). Written as the table-driven C of
OpenSSL's ``aes_core.c`` for a 32-bit MCU: the 128-bit state is four ``uint32_t`` words, each a
column read big-endian (``s0 = in[0] << 24 | in[1] << 16 | in[2] << 8 | in[3]``); one round is
16 lookups in four ``const uint32_t Te[4][256]`` tables (SubBytes, ShiftRows and MixColumns
folded together) and four XORs with the round key; the last round has no MixColumns and uses the
S-box. Every intermediate is a u8 (a byte index) or a u32 (a word).

Tables (``const`` in C, 4 x 1 KiB + 256 B of flash) are generated at import from their
definition, as ``firmware.e2e`` builds its CRC table, never typed in by hand:

* ``SBOX[x]`` (FIPS-197 5.1.1): the multiplicative inverse of ``x`` in GF(2^8) modulo
  ``x^8 + x^4 + x^3 + x + 1`` (0 maps to 0), then the affine map
  ``b ^ rotl8(b, 1) ^ rotl8(b, 2) ^ rotl8(b, 3) ^ rotl8(b, 4) ^ 0x63``. The inverse comes from
  log/antilog tables over the generator 0x03.
* ``TE0[x] = (2s, s, s, 3s)`` packed big-endian with ``s = SBOX[x]`` (one MixColumns column);
  ``TE1..TE3`` are it rotated right by 8, 16, 24 bits.

Cost in CPython 3.11: see ``bench/secoc.py`` (one block is 160 table lookups). In C on a
Cortex-M4 at 100 MHz a table-driven AES-128 block is of the order of 1-2 k cycles. The lookups
are data-dependent: fine on a cacheless Cortex-M0/M3/M4; on a part with a data cache (M7) the C
port should use a constant-time bitsliced AES (docs/secoc.md).
"""

from __future__ import annotations

from typing import Final

from odocan.firmware.fixmath import U8_MAX, U32_MAX, u8, u32

AES128_KEY_BYTES: Final = 16
AES_BLOCK_BYTES: Final = 16
AES128_ROUNDS: Final = 10
AES128_ROUND_KEY_WORDS: Final = 4 * (AES128_ROUNDS + 1)  # 44 u32: w[0..43] of FIPS-197 5.2
GF_POLY_LOW: Final = 0x1B  # x^8 = x^4 + x^3 + x + 1 in GF(2^8)
SBOX_AFFINE_CONST: Final = 0x63
RCON: Final[tuple[u8, ...]] = (0x01, 0x02, 0x04, 0x08, 0x10, 0x20, 0x40, 0x80, 0x1B, 0x36)


def xtime(b: u8) -> u8:
    """Multiplication by x (0x02) in GF(2^8) (FIPS-197 4.2.1): ``(b << 1) ^ (0x1B if b & 0x80)``."""
    doubled = b << 1
    if doubled & 0x100:
        doubled ^= 0x100 | GF_POLY_LOW
    return doubled


def _rotl8(b: u8, n: int) -> u8:
    """``(uint8_t)(b << n | b >> (8 - n))``, 1 <= n <= 7."""
    return ((b << n) | (b >> (8 - n))) & U8_MAX


def _gf_log_tables() -> tuple[tuple[u8, ...], tuple[u8, ...]]:
    """``(exp, log)`` over the generator 0x03: ``exp[i] = 3^i``, ``log[3^i] = i`` (not log 0)."""
    exp = [0] * 256
    log = [0] * 256
    value = 1
    for i in range(255):
        exp[i] = value
        log[value] = i
        value ^= xtime(value)  # value * 3 = value * 2 ^ value
    exp[255] = exp[0]
    return tuple(exp), tuple(log)


def _sbox_table() -> tuple[u8, ...]:
    """FIPS-197 5.1.1: the S-box (a ``const uint8_t[256]`` in C)."""
    exp, log = _gf_log_tables()
    table: list[u8] = []
    for x in range(256):
        inverse = exp[255 - log[x]] if x else 0
        affine = inverse
        for n in (1, 2, 3, 4):
            affine ^= _rotl8(inverse, n)
        table.append(affine ^ SBOX_AFFINE_CONST)
    return tuple(table)


SBOX: Final[tuple[u8, ...]] = _sbox_table()


def _ror32(word: u32, n: int) -> u32:
    """``(uint32_t)(word >> n | word << (32 - n))``, 1 <= n <= 31."""
    return ((word >> n) | (word << (32 - n))) & U32_MAX


def _te_tables() -> tuple[tuple[u32, ...], tuple[u32, ...], tuple[u32, ...], tuple[u32, ...]]:
    """The four round tables ``Te0..Te3`` (``const uint32_t[256]`` each)."""
    te0: list[u32] = []
    for x in range(256):
        s = SBOX[x]
        s2 = xtime(s)
        te0.append((s2 << 24) | (s << 16) | (s << 8) | (s2 ^ s))
    te1 = [_ror32(w, 8) for w in te0]
    te2 = [_ror32(w, 16) for w in te0]
    te3 = [_ror32(w, 24) for w in te0]
    return tuple(te0), tuple(te1), tuple(te2), tuple(te3)


TE0, TE1, TE2, TE3 = _te_tables()


def _sub_word(word: u32) -> u32:
    """FIPS-197 SubWord: the S-box on each byte of a word."""
    sb = SBOX
    return (
        (sb[word >> 24] << 24)
        | (sb[(word >> 16) & U8_MAX] << 16)
        | (sb[(word >> 8) & U8_MAX] << 8)
        | sb[word & U8_MAX]
    )


def load_be32(data: bytes | bytearray, offset: int) -> u32:
    """Big-endian u32 at ``data[offset..offset+3]`` (OpenSSL's ``GETU32``)."""
    return (
        (data[offset] << 24) | (data[offset + 1] << 16) | (data[offset + 2] << 8) | data[offset + 3]
    )


def store_be32(out: bytearray, offset: int, word: u32) -> None:
    """Write u32 ``word`` big-endian at ``out[offset..offset+3]`` (OpenSSL's ``PUTU32``)."""
    out[offset] = word >> 24
    out[offset + 1] = (word >> 16) & U8_MAX
    out[offset + 2] = (word >> 8) & U8_MAX
    out[offset + 3] = word & U8_MAX


def expand_key(key: bytes | bytearray) -> tuple[u32, ...]:
    """FIPS-197 5.2 KeyExpansion of a 16-byte key: the 44 round-key words ``w[0..43]``.

    Provisioning time, once per key (C: ``void aes128_expand_key(const uint8_t key[16],
    uint32_t rk[44])``). Precondition: ``len(key) == 16`` (the caller checks it).
    """
    w: list[u32] = [load_be32(key, 4 * i) for i in range(4)]
    for i in range(4, AES128_ROUND_KEY_WORDS):
        temp = w[i - 1]
        if i & 3 == 0:
            temp = _sub_word(((temp << 8) & U32_MAX) | (temp >> 24)) ^ (RCON[(i >> 2) - 1] << 24)
        w.append(w[i - 4] ^ temp)
    return tuple(w)


def encrypt_words(rk: tuple[u32, ...], s0: u32, s1: u32, s2: u32, s3: u32) -> tuple[u32, ...]:
    """AES-128 Cipher (FIPS-197 5.1) of the state columns ``s0..s3`` under round keys ``rk``.

    C: ``void aes128_encrypt_words(const uint32_t rk[44], uint32_t s[4])``; every ``t*``/``s*``
    a u32, every table index a u8.
    """
    t0, t1, t2, t3 = TE0, TE1, TE2, TE3
    s0 ^= rk[0]
    s1 ^= rk[1]
    s2 ^= rk[2]
    s3 ^= rk[3]
    for r in range(4, 4 * AES128_ROUNDS, 4):  # rounds 1..9
        a0 = t0[s0 >> 24] ^ t1[(s1 >> 16) & 0xFF] ^ t2[(s2 >> 8) & 0xFF] ^ t3[s3 & 0xFF] ^ rk[r]
        a1 = t0[s1 >> 24] ^ t1[(s2 >> 16) & 0xFF] ^ t2[(s3 >> 8) & 0xFF] ^ t3[s0 & 0xFF] ^ rk[r + 1]
        a2 = t0[s2 >> 24] ^ t1[(s3 >> 16) & 0xFF] ^ t2[(s0 >> 8) & 0xFF] ^ t3[s1 & 0xFF] ^ rk[r + 2]
        a3 = t0[s3 >> 24] ^ t1[(s0 >> 16) & 0xFF] ^ t2[(s1 >> 8) & 0xFF] ^ t3[s2 & 0xFF] ^ rk[r + 3]
        s0, s1, s2, s3 = a0, a1, a2, a3
    sb = SBOX
    last = 4 * AES128_ROUNDS
    return (
        _last_round_word(sb, s0, s1, s2, s3) ^ rk[last],
        _last_round_word(sb, s1, s2, s3, s0) ^ rk[last + 1],
        _last_round_word(sb, s2, s3, s0, s1) ^ rk[last + 2],
        _last_round_word(sb, s3, s0, s1, s2) ^ rk[last + 3],
    )


def _last_round_word(sb: tuple[u8, ...], a: u32, b: u32, c: u32, d: u32) -> u32:
    """One output column of the final round: SubBytes and ShiftRows, no MixColumns."""
    return (
        (sb[a >> 24] << 24)
        | (sb[(b >> 16) & 0xFF] << 16)
        | (sb[(c >> 8) & 0xFF] << 8)
        | sb[d & 0xFF]
    )
