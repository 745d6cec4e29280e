"""Generate ``firmware/c/aes_tables.h``: the AES-128 S-box and round tables as ``static const``.

A host-side build step, like ``tools/gen_trig_tables.py``: ``python tools/gen_aes_tables.py``
rewrites the header, ``--check`` only compares (exit 1 when it differs; ``make -C firmware/c
tables-check`` runs it). On an MCU the tables live in flash (256 B + 4 x 1 KiB), so the C
firmware computes nothing at run time.

The tables are computed here from FIPS-197's definitions, independently of ``firmware/aes.py``
(which builds its S-box from log/antilog tables over the generator 0x03): the multiplicative
inverse by exhaustive search over GF(2^8) products (shift-and-add multiplication modulo
x^8 + x^4 + x^3 + x + 1), then the affine map of FIPS-197 5.1.1 written bit by bit.
``tests/test_aes_tables.py`` compares the two, the header, and FIPS-197's own S-box entries.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from pathlib import Path

TARGET = Path(__file__).resolve().parent.parent / "firmware" / "c" / "aes_tables.h"
AES_POLY = 0x11B  # x^8 + x^4 + x^3 + x + 1
AFFINE_C = 0x63  # FIPS-197 5.1.1's constant c = {01100011}


def gf_mul(a: int, b: int) -> int:
    """a * b in GF(2^8): carry-less shift-and-add, reduced modulo ``AES_POLY``."""
    product = 0
    while b:
        if b & 1:
            product ^= a
        a <<= 1
        if a & 0x100:
            a ^= AES_POLY
        b >>= 1
    return product


def gf_inverse(x: int) -> int:
    """The multiplicative inverse of ``x`` in GF(2^8) (0 maps to 0), by exhaustive search."""
    if x == 0:
        return 0
    return next(y for y in range(1, 256) if gf_mul(x, y) == 1)


def affine(b: int) -> int:
    """FIPS-197 (5.1): b'_i = b_i ^ b_(i+4) ^ b_(i+5) ^ b_(i+6) ^ b_(i+7) ^ c_i, mod 8."""
    out = 0
    for i in range(8):
        bit = 0
        for j in (0, 4, 5, 6, 7):
            bit ^= (b >> ((i + j) % 8)) & 1
        out |= (bit ^ ((AFFINE_C >> i) & 1)) << i
    return out


def sbox() -> list[int]:
    """FIPS-197 Figure 7: S(x) = affine(x^-1)."""
    return [affine(gf_inverse(x)) for x in range(256)]


def _ror32(word: int, n: int) -> int:
    return ((word >> n) | (word << (32 - n))) & 0xFFFF_FFFF


def te_tables(s: list[int]) -> list[list[int]]:
    """Te0..Te3: Te0[x] = (2.S[x], S[x], S[x], 3.S[x]) as a big-endian word (one MixColumns
    column of a SubBytes byte), Te_k = Te0 rotated right by 8k bits."""
    te0 = [(gf_mul(v, 2) << 24) | (v << 16) | (v << 8) | gf_mul(v, 3) for v in s]
    return [te0, *([_ror32(w, 8 * k) for w in te0] for k in (1, 2, 3))]


def compute() -> dict[str, list[int]]:
    """Every table of the header, by name."""
    s = sbox()
    te0, te1, te2, te3 = te_tables(s)
    return {"SBOX": s, "TE0": te0, "TE1": te1, "TE2": te2, "TE3": te3}


def _array(name: str, values: list[int]) -> Iterator[str]:
    """A ``static const`` array: bytes 16 a line (a row of FIPS-197 Figure 7), words 6 a line."""
    byte = name == "SBOX"
    c_type, per_line, width = ("uint8_t", 16, 2) if byte else ("uint32_t", 6, 8)
    suffix = "u"
    yield f"static const {c_type} {name}[256] = {{"
    for start in range(0, 256, per_line):
        row = values[start : start + per_line]
        yield "    " + " ".join(f"0x{v:0{width}X}{suffix}," for v in row)
    yield "};"


def render() -> str:
    """The whole text of ``firmware/c/aes_tables.h``."""
    lines = [
        "/* AES-128 tables of firmware/c/aes.c: GENERATED, do not edit.",
        " *",
        " * Written by `python tools/gen_aes_tables.py` from FIPS-197's definitions: the",
        " * S-box (5.1.1: affine map of the GF(2^8) inverse) and the four round tables Te0..Te3",
        " * (SubBytes and MixColumns of one byte, Te_k = Te0 rotated right by 8k). static const:",
        " * the tables live in flash (256 B + 4 KiB). Included by aes.c only.",
        " */",
        "#ifndef ODOCAN_AES_TABLES_H",
        "#define ODOCAN_AES_TABLES_H",
        "",
        "#include <stdint.h>",
        "",
    ]
    for name, values in compute().items():
        lines.extend(_array(name, values))
        lines.append("")
    lines.append("#endif")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Write (or with ``--check`` compare) the header; returns the exit code."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare only; exit 1 if it differs")
    parser.add_argument("--output", type=Path, default=TARGET, help=f"default: {TARGET}")
    args = parser.parse_args(argv)
    text = render()
    if args.check:
        same = args.output.exists() and args.output.read_text(encoding="utf-8") == text
        print(f"{args.output}: {'up to date' if same else 'DIFFERS'}")
        return 0 if same else 1
    args.output.write_text(text, encoding="utf-8")
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
