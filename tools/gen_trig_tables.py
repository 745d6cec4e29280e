"""Generate ``firmware/trig_tables.py``: the integer constants of ``firmware/trig.py``.

A host-side build step: ``python tools/gen_trig_tables.py`` rewrites the file, ``--check`` only
compares (exit 1 when it differs). ``--c`` does the same for the C port's header,
``firmware/c/trig_tables.h``, from the same values (``--c --check`` compares it). Every
constant is an exact rational function of pi, evaluated here with :mod:`decimal` at
``PREC_DIGITS`` significant digits (float64 holds 53 bits, too few for a Q62 table) and then
rounded to the nearest integer. ``_round_checked`` refuses a value that
lies within ``1e-40`` of a rounding boundary, so every entry is provably correctly rounded.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Iterator
from decimal import ROUND_HALF_EVEN, Decimal, getcontext, localcontext
from pathlib import Path

PREC_DIGITS = 100
TARGET = Path(__file__).resolve().parent.parent / "firmware" / "trig_tables.py"
TARGET_C = Path(__file__).resolve().parent.parent / "firmware" / "c" / "trig_tables.h"
# The C type of each table (the scalars are u64 constants, the shifts unsigned ints).
_C_ARRAY_TYPES: dict[str, str] = {"SIN_Q62": "int64_t", "ATAN_BAM48": "uint64_t"}

SIN_KNOTS = 256  # quarter wave in 256 steps: knot spacing 2^22 BAM32 LSB
ATAN_KNOTS = 256  # atan(k / 256) for k = 0..256
SIN_K3_SHIFT = 58
SIN_K2_SHIFT = 27
SIN_K4_SHIFT = 62
ATAN_K1_SHIFT = 26


def _pi() -> Decimal:
    """pi by Machin's formula, 16 atan(1/5) - 4 atan(1/239), in the current context."""
    return 16 * _atan_series(Decimal(1) / 5) - 4 * _atan_series(Decimal(1) / 239)


def _atan_series(x: Decimal) -> Decimal:
    """atan(x) by its Taylor series; fast for |x| <= 0.2 (the caller reduces the argument)."""
    eps = Decimal(10) ** (-(getcontext().prec + 5))
    x2 = x * x
    term = x
    total = x
    n = 1
    while abs(term) > eps:
        term = -term * x2
        n += 2
        total += term / n
    return total


def _atan(x: Decimal) -> Decimal:
    """atan(x) for 0 <= x <= 1: two half-angle reductions (to <= tan(pi/16)), then the series."""
    for _ in range(2):
        x = x / (1 + (1 + x * x).sqrt())
    return 4 * _atan_series(x)


def _sin(x: Decimal) -> Decimal:
    """sin(x) by its Taylor series, for 0 <= x <= pi/2."""
    eps = Decimal(10) ** (-(getcontext().prec + 5))
    x2 = x * x
    term = x
    total = x
    n = 1
    while abs(term) > eps:
        term = -term * x2 / ((n + 1) * (n + 2))
        n += 2
        total += term
    return total


def _round_checked(value: Decimal) -> int:
    """Nearest integer to ``value``; raises if ``value`` is too close to a half for certainty."""
    nearest = value.to_integral_value(rounding=ROUND_HALF_EVEN)
    if abs(abs(value - nearest) - Decimal("0.5")) < Decimal("1e-40"):
        raise ArithmeticError(f"cannot round {value} with certainty")
    return int(nearest)


def compute() -> dict[str, int | list[int]]:
    """Every constant of the generated module, by name."""
    with localcontext() as ctx:
        ctx.prec = PREC_DIGITS
        pi = _pi()
        omega = 2 * pi / 2**32  # rad per BAM32 LSB
        rad_to_bam48 = Decimal(2**48) / (2 * pi)
        atan_k1 = Decimal(2**9) * 2**ATAN_K1_SHIFT / (2 * pi)
        return {
            "SIN_Q62": [
                _round_checked(_sin(pi / 2 * k / SIN_KNOTS) * 2**62) for k in range(SIN_KNOTS + 1)
            ],
            "SIN_STEP_Q64": _round_checked(omega * 2**64),
            "SIN_K3_SHIFT": SIN_K3_SHIFT,
            "SIN_K2_SHIFT": SIN_K2_SHIFT,
            "SIN_K4_SHIFT": SIN_K4_SHIFT,
            "SIN_K3": _round_checked(omega**3 / 6 * 2 ** (64 + SIN_K3_SHIFT)),
            "SIN_K2": _round_checked(omega**2 / 2 * 2 ** (64 + SIN_K2_SHIFT)),
            "SIN_K4": _round_checked(omega**4 / 24 * 2 ** (64 + SIN_K2_SHIFT + SIN_K4_SHIFT)),
            "ATAN_BAM48": [
                _round_checked(_atan(Decimal(k) / ATAN_KNOTS) * rad_to_bam48)
                for k in range(ATAN_KNOTS + 1)
            ],
            "ATAN_K1_SHIFT": ATAN_K1_SHIFT,
            "ATAN_K1": _round_checked(atan_k1),
            "ATAN_K3": _round_checked(atan_k1 * 2 / 3),
        }


_DOCS: dict[str, str] = {
    "SIN_Q62": "sin(k * pi/512) in Q62 (i64), k = 0..256: the quarter wave, knots 2^22 BAM32 apart",
    "SIN_STEP_Q64": "2*pi / 2^32 in Q64 (u64): radians per BAM32 LSB",
    "SIN_K3": f"(2*pi/2^32)^3 / 6 * 2^(64+{SIN_K3_SHIFT}) (u32): the theta^3/6 coefficient",
    "SIN_K2": f"(2*pi/2^32)^2 / 2 * 2^(64+{SIN_K2_SHIFT}) (u32): the theta^2/2 coefficient",
    "SIN_K4": (
        f"(2*pi/2^32)^4 / 24 * 2^(64+{SIN_K2_SHIFT}+{SIN_K4_SHIFT}) (u32):"
        " the theta^4/24 coefficient"
    ),
    "SIN_K3_SHIFT": "right shift after the product with SIN_K3",
    "SIN_K2_SHIFT": "right shift after the product with SIN_K2",
    "SIN_K4_SHIFT": "right shift after the product with SIN_K4",
    "ATAN_K1_SHIFT": "right shift after the product with ATAN_K1",
    "ATAN_BAM48": "atan(k / 256) in BAM48 (2^48 per turn, u64), k = 0..256",
    "ATAN_K1": f"2^9 / (2*pi) * 2^{ATAN_K1_SHIFT} (u64): Q39 radians to BAM48, scaled",
    "ATAN_K3": f"2^9 / (2*pi) * 2^{ATAN_K1_SHIFT} * 2/3 (u32): the u^2/3 term of atan(u)",
}


def _hex(value: int) -> str:
    """``value`` as an upper-case hex literal in groups of 4 digits (as ``ruff format`` has it)."""
    return "0x" + f"{value:_x}".upper()


def _literal_lines(name: str, value: int | list[int]) -> Iterator[str]:
    """The Python source lines that bind ``name``: a hex literal or a tuple of them, 4 a line."""
    yield f"# {_DOCS[name]}"
    if isinstance(value, int):
        yield f"{name}: Final = {value if name.endswith('_SHIFT') else _hex(value)}"
        return
    yield "# fmt: off"
    yield f"{name}: Final[tuple[int, ...]] = ("
    for start in range(0, len(value), 4):
        yield "    " + " ".join(f"{_hex(v)}," for v in value[start : start + 4])
    yield ")"
    yield "# fmt: on"


def render(values_fn: Callable[[], dict[str, int | list[int]]] = compute) -> str:
    """The whole text of ``firmware/trig_tables.py``."""
    lines = [
        '"""Integer constants of ``firmware/trig.py``: GENERATED, do not edit.',
        "",
        "Written by ``python tools/gen_trig_tables.py``, which evaluates",
        f"every constant with ``decimal`` at {PREC_DIGITS} digits and rounds it to the nearest",
        "integer (correctly rounded: the generator checks the distance to each rounding boundary).",
        "In C these are ``static const`` arrays in flash.",
        '"""',
        "",
        "from __future__ import annotations",
        "",
        "from typing import Final",
        "",
    ]
    for name, value in values_fn().items():
        lines.extend(_literal_lines(name, value))
        lines.append("")
    return "\n".join(lines)


def _c_lines(name: str, value: int | list[int]) -> Iterator[str]:
    """The C lines that define ``name``: a ``#define`` or a ``static const`` array, 3 a line."""
    yield f"/* {_DOCS[name]} */"
    if isinstance(value, int):
        literal = f"{value}u" if name.endswith("_SHIFT") else f"UINT64_C(0x{value:X})"
        yield f"#define {name} {literal}"
        return
    c_type = _C_ARRAY_TYPES[name]
    macro = c_type.upper()[:-2]  # int64_t -> INT64: the INT64_C / UINT64_C literal macro
    yield f"static const {c_type} {name}[{len(value)}] = {{"
    for start in range(0, len(value), 3):
        yield "    " + " ".join(f"{macro}_C(0x{v:X})," for v in value[start : start + 3])
    yield "};"


def render_c(values_fn: Callable[[], dict[str, int | list[int]]] = compute) -> str:
    """The whole text of ``firmware/c/trig_tables.h`` (the same values as ``render``)."""
    lines = [
        "/* Integer constants of firmware/c/trig.c: GENERATED, do not edit.",
        " *",
        " * Written by `python tools/gen_trig_tables.py --c` from the same values as",
        " * firmware/trig_tables.py (decimal at "
        f"{PREC_DIGITS} digits, every entry correctly rounded).",
        " * static const: the tables live in flash. Included by trig.c only.",
        " */",
        "#ifndef ODOCAN_TRIG_TABLES_H",
        "#define ODOCAN_TRIG_TABLES_H",
        "",
        "#include <stdint.h>",
        "",
    ]
    for name, value in values_fn().items():
        lines.extend(_c_lines(name, value))
        lines.append("")
    lines.append("#endif")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Write (or with ``--check`` compare) the generated module; returns the exit code."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare only; exit 1 if it differs")
    parser.add_argument("--c", action="store_true", help="the C header firmware/c/trig_tables.h")
    parser.add_argument("--output", type=Path, help=f"default: {TARGET} (with --c: {TARGET_C})")
    args = parser.parse_args(argv)
    text = render_c() if args.c else render()
    if args.output is None:
        args.output = TARGET_C if args.c else TARGET
    if args.check:
        same = args.output.exists() and args.output.read_text(encoding="utf-8") == text
        print(f"{args.output}: {'up to date' if same else 'DIFFERS'}")
        return 0 if same else 1
    args.output.write_text(text, encoding="utf-8")
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
