"""The C firmware's AES tables (``firmware/c/aes_tables.h``, ``static const`` in flash): generated
by ``tools/gen_aes_tables.py`` from FIPS-197's definitions, checked three ways.

1. The committed header is what the generator writes today (regenerate and compare).
2. The generator's tables equal ``firmware/aes.py``'s, computed another way (log/antilog tables
   over the generator 0x03 against an exhaustive inverse search and a bitwise affine map).
3. Entries printed in FIPS-197 itself (Figure 7 and the worked example of 5.1.1).
The C cipher built on the header is proven against RFC 4493 in ``tests/test_aes_cmac.py``.
"""

from __future__ import annotations

from pathlib import Path

from odocan.firmware import aes
from tools import gen_aes_tables

ROOT = Path(__file__).resolve().parent.parent


def test_the_committed_header_is_the_generators_output(tmp_path: Path) -> None:
    assert gen_aes_tables.render() == gen_aes_tables.TARGET.read_text(encoding="utf-8")
    stale = tmp_path / "aes_tables.h"
    stale.write_text(gen_aes_tables.render().replace("0x63u", "0x64u", 1))
    assert gen_aes_tables.main(["--check", "--output", str(stale)]) == 1
    assert gen_aes_tables.main(["--output", str(stale)]) == 0
    assert gen_aes_tables.main(["--check", "--output", str(stale)]) == 0


def test_the_generated_tables_are_the_python_firmwares() -> None:
    tables = gen_aes_tables.compute()
    assert tables["SBOX"] == list(aes.SBOX)
    python = {"TE0": aes.TE0, "TE1": aes.TE1, "TE2": aes.TE2, "TE3": aes.TE3}
    for name, table in python.items():
        assert tables[name] == list(table), name


def test_fips_197_entries() -> None:
    sbox = gen_aes_tables.sbox()
    # Figure 7: row 0 and S(0x53) = 0xED (5.1.1's example); a permutation with no fixed point
    assert sbox[:16] == [0x63, 0x7C, 0x77, 0x7B, 0xF2, 0x6B, 0x6F, 0xC5,
                         0x30, 0x01, 0x67, 0x2B, 0xFE, 0xD7, 0xAB, 0x76]
    assert sbox[0x53] == 0xED
    assert sbox[0xFF] == 0x16
    assert sorted(sbox) == list(range(256))
    assert all(sbox[x] != x and sbox[x] != x ^ 0xFF for x in range(256))
    assert gen_aes_tables.gf_mul(0x57, 0x83) == 0xC1  # 4.2's worked product


def test_the_c_source_keeps_no_table_in_ram() -> None:
    source = (ROOT / "firmware" / "c" / "aes.c").read_text()
    header = gen_aes_tables.TARGET.read_text()
    assert '#include "aes_tables.h"' in source
    assert "static const uint8_t SBOX[256]" in header
    assert all(f"static const uint32_t TE{k}[256]" in header for k in range(4))
    assert "static uint8_t SBOX" not in source
    assert "static uint32_t TE" not in source
