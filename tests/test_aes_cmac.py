"""The firmware's AES-128 and AES-CMAC against FIPS-197, RFC 4493 and ``cryptography``."""

from __future__ import annotations

import random

import pytest
from cryptography.hazmat.primitives.ciphers import Cipher, algorithms, modes
from cryptography.hazmat.primitives.cmac import CMAC

from odocan.firmware.aes import SBOX, TE0, TE3, encrypt_words, expand_key, xtime
from odocan.firmware.cmac import cmac, cmac_key

RFC4493_KEY = bytes.fromhex("2b7e151628aed2a6abf7158809cf4f3c")
RFC4493_MESSAGE = bytes.fromhex(
    "6bc1bee22e409f96e93d7e117393172a"
    "ae2d8a571e03ac9c9eb76fac45af8e51"
    "30c81c46a35ce411e5fbc1191a0a52ef"
    "f69f2445df4f9b17ad2b417be66c3710"
)
# RFC 4493 section 4: examples 1-4 (Mlen 0, 128, 320, 512 bits).
RFC4493_VECTORS = [
    (0, "bb1d6929e95937287fa37d129b756746"),
    (16, "070a16b46b4d4144f79bdd9dd04a287c"),
    (40, "dfa66747de9ae63030ca32611497c827"),
    (64, "51f0bebf7e3b9d92fc49741779363cfe"),
]


def encrypt_block(rk: tuple[int, ...], block: bytes) -> bytes:
    """One 16-byte block through the firmware's ``encrypt_words`` (big-endian columns, FIPS-197
    3.4), as C's ``aes_cmac`` loads and stores the words around ``aes128_encrypt_words``."""
    columns = [int.from_bytes(block[4 * i : 4 * i + 4], "big") for i in range(4)]
    words = encrypt_words(rk, *columns)
    return b"".join(word.to_bytes(4, "big") for word in words)


def _gf_mul(a: int, b: int) -> int:
    """GF(2^8) product modulo x^8 + x^4 + x^3 + x + 1, bit by bit (independent of the module)."""
    product = 0
    for _ in range(8):
        if b & 1:
            product ^= a
        a = ((a << 1) ^ 0x11B) if a & 0x80 else a << 1
        b >>= 1
    return product


def _reference_sbox(x: int) -> int:
    """FIPS-197 5.1.1 from its definition: brute-force inverse, then the affine map bit by bit."""
    inverse = next((y for y in range(1, 256) if _gf_mul(x, y) == 1), 0)
    out = 0
    for i in range(8):
        bit = 0
        for j in (0, 4, 5, 6, 7):
            bit ^= (inverse >> ((i + j) % 8)) & 1
        out |= (bit ^ ((0x63 >> i) & 1)) << i
    return out


def test_sbox_is_the_fips197_definition() -> None:
    assert list(SBOX) == [_reference_sbox(x) for x in range(256)]
    assert sorted(SBOX) == list(range(256))  # a permutation
    assert (SBOX[0x00], SBOX[0x53], SBOX[0xFF]) == (0x63, 0xED, 0x16)  # FIPS-197 Figure 7


def test_round_tables_fold_mixcolumns() -> None:
    for x in (0, 1, 0x53, 0x80, 0xFF):
        s = SBOX[x]
        assert TE0[x] == (xtime(s) << 24) | (s << 16) | (s << 8) | _gf_mul(s, 3)
        assert TE3[x] == (s << 24) | (s << 16) | (_gf_mul(s, 3) << 8) | xtime(s)


def test_fips197_appendix_c1_vector() -> None:
    rk = expand_key(bytes(range(16)))
    plaintext = bytes.fromhex("00112233445566778899aabbccddeeff")
    assert encrypt_block(rk, plaintext).hex() == "69c4e0d86a7b0430d8cdb78070b4c55a"


def test_fips197_appendix_a1_key_expansion() -> None:
    rk = expand_key(RFC4493_KEY)  # FIPS-197 A.1 uses the same key
    assert rk[4] == 0xA0FAFE17
    assert rk[43] == 0xB6630CA6
    assert len(rk) == 44


@pytest.mark.parametrize(("length", "tag"), RFC4493_VECTORS)
def test_rfc4493_vectors(length: int, tag: str) -> None:
    assert cmac(cmac_key(RFC4493_KEY), RFC4493_MESSAGE[:length]).hex() == tag


def test_rfc4493_subkeys() -> None:
    key = cmac_key(RFC4493_KEY)
    assert key.k1 == (0xFBEED618, 0x35713366, 0x7C85E08F, 0x7236A8DE)
    assert key.k2 == (0xF7DDAC30, 0x6AE266CC, 0xF90BC11E, 0xE46D513B)


def _reference_cmac(key: bytes, message: bytes) -> bytes:
    mac = CMAC(algorithms.AES(key))
    mac.update(message)
    return mac.finalize()


def test_aes_matches_cryptography_on_random_keys() -> None:
    rng = random.Random(4493)
    for _ in range(1000):
        key = rng.randbytes(16)
        block = rng.randbytes(16)
        encryptor = Cipher(algorithms.AES(key), modes.ECB()).encryptor()
        expected = encryptor.update(block) + encryptor.finalize()
        assert encrypt_block(expand_key(key), block) == expected


def test_cmac_matches_cryptography_on_random_keys_and_messages() -> None:
    """1200 random keys, messages of every length 0..80 bytes (every padding case, 0..5 blocks)."""
    rng = random.Random(18)
    for i in range(1200):
        key = rng.randbytes(16)
        message = rng.randbytes(i % 81)
        assert cmac(cmac_key(key), message) == _reference_cmac(key, message), (key, message)
