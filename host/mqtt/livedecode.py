"""cantools' per-frame ``Message.decode(data, decode_choices=False)``, compiled once per message.

The bridge decodes every accepted frame of every robot, one at a time (a fleet of 50 robots: some
15 000 frames a second). cantools unpacks each frame with bitstruct and walks its codec tree per
call; ``LiveDecoder`` reads the same tree once (cantools' own ``_codecs``: signals, multiplexers,
their selected sub-trees) and decodes a frame as one little-endian integer, a shift and a mask per
signal, a sign extension, and the signal's own cantools conversion (``raw_to_scaled``: the very
same arithmetic, so the same ints and floats; an identity conversion, which returns the raw
integer, is not called). Multiplexed messages select their sub-tree by the
multiplexer's value as cantools does; a value the DBC does not define is cantools'
``DecodeError``, and so is a payload shorter than the message (a longer one is cut, as cantools'
``allow_excess``). A message this form does not cover (a big-endian or float signal, a container)
is decoded by cantools itself. tests/test_mqtt_livedecode.py holds it to cantools on random
payloads of every message of the DBC.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from cantools.database.can import Message
from cantools.database.conversion import IdentityConversion
from cantools.database.errors import DecodeError

# name, shift, mask, sign, scale (None: cantools' IdentityConversion, whose scaling is the raw
# value itself: not called)
Field = tuple[str, int, int, int, Callable[[int, bool], Any] | None]


@dataclass(frozen=True)
class _Node:
    """One level of a message's codec tree: its signals, then its multiplexers' sub-trees."""

    fields: tuple[Field, ...]
    muxes: tuple[tuple[str, dict[int, _Node]], ...]


class LiveDecoder:
    """``decode(data)`` == ``message.decode(data, decode_choices=False)`` (module docstring)."""

    def __init__(self, message: Message) -> None:
        self.message = message
        self.length = message.length
        codecs = message._codecs
        self._root = None if codecs is None or not _covered(message) else _compile(codecs)

    def decode(self, data: bytes) -> dict[str, Any]:
        """The frame's signal values by name (raw numbers scaled, enums as numbers)."""
        root = self._root
        if root is None:
            return dict(self.message.decode_simple(data, decode_choices=False))
        if len(data) < self.length:
            raise DecodeError(f"Wrong data size: {len(data)} instead of {self.length} bytes")
        word = int.from_bytes(data[:self.length], "little")
        out: dict[str, Any] = {}
        _decode(root, word, out)
        return out


def _covered(message: Message) -> bool:
    """Little-endian integer signals of a plain (non-container) message of at most 8 bytes."""
    return (not message.is_container and message.length <= 8
            and all(s.byte_order == "little_endian" and not s.is_float for s in message.signals))


def _compile(node: Any) -> _Node:
    fields = tuple(
        (s.name, s.start, (1 << s.length) - 1, 1 << (s.length - 1) if s.is_signed else 0,
         None if type(s.conversion) is IdentityConversion else s.conversion.raw_to_scaled)
        for s in node["signals"]
    )
    muxes = tuple((name, {value: _compile(sub) for value, sub in by_value.items()})
                  for name, by_value in node["multiplexers"].items())
    return _Node(fields, muxes)


def _decode(node: _Node, word: int, out: dict[str, Any]) -> None:
    for name, shift, mask, sign, scale in node.fields:
        raw = (word >> shift) & mask
        if raw & sign:
            raw -= sign << 1
        out[name] = raw if scale is None else scale(raw, False)
    for name, by_value in node.muxes:
        sub = by_value.get(int(out[name]))
        if sub is None:
            raise DecodeError(f"expected multiplexer id {sorted(by_value)}, but got "
                              f"{int(out[name])}")
        _decode(sub, word, out)
