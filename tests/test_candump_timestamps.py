"""candump timestamps parse to the very double ``float(text)`` gives, at every digit count the fast
path takes (up to 18 digits: a Unix time in ns has 19 and takes the slow path)."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from odocan.host.io.candump import parse_candump


@st.composite
def timestamp_texts(draw: st.DrawFn) -> list[str]:
    """One group of timestamps of one width (the fast path parses a line-length group at once)."""
    int_digits = draw(st.integers(1, 12))
    frac_digits = draw(st.integers(1, 18 - int_digits))
    ints = st.integers(0, 10**int_digits - 1).map(lambda v: str(v).zfill(int_digits))
    fracs = st.integers(0, 10**frac_digits - 1).map(lambda v: str(v).zfill(frac_digits))
    pairs = draw(st.lists(st.tuples(ints, fracs), min_size=1, max_size=40))
    return [f"{i}.{f}" for i, f in pairs]


@settings(max_examples=300, deadline=None)
@given(timestamp_texts())
def test_timestamps_are_floats_of_their_text(texts: list[str]) -> None:
    log = "".join(f"({t}) can0 123#0011223344556677\n" for t in texts).encode()
    frames = parse_candump(log)
    assert [float(v) for v in frames.timestamp_s] == [float(t) for t in texts]

