"""cantools' per-frame ``Message.decode(data, decode_choices=False)``, compiled once per message.

The bridge decodes every accepted frame of every robot, one at a time (a fleet of 50 robots: some
15 000 frames a second). cantools unpacks each frame with bitstruct and walks its codec tree per
call; ``LiveDecoder`` reads the same tree once (cantools' own ``_codecs``: signals, multiplexers,
their selected sub-trees) and decodes a frame as one little-endian integer, a shift and a mask per
signal, a sign extension, and the signal's own cantools conversion (``raw_to_scaled``: the very
same arithmetic, so the same ints and floats; an identity conversion, which returns the raw
integer, is not called; a linear one is written out as its ``raw * scale + offset``, the constants
by their exact ``repr``: a message without multiplexers is decoded by one function made for it, one
dict display of its signals, each read from the bytes it spans). Multiplexed messages select their
sub-tree by the multiplexer's value as cantools does (one multiplexer with plain pages, as
ODOM_STATUS and SIM_TRUTH: one such function per page, picked by the multiplexer's value); a value
the DBC does not define is cantools' ``DecodeError``, and so is a payload shorter than the message
(a longer one is cut, as cantools' ``allow_excess``). A message this form does not cover (a
big-endian or float signal, a container) is decoded by cantools itself.
tests/test_mqtt_livedecode.py holds it to cantools on random payloads of every message of the DBC.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from cantools.database.can import Message
from cantools.database.conversion import (
    BaseConversion,
    IdentityConversion,
    LinearConversion,
    LinearIntegerConversion,
    NamedSignalConversion,
)
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
    """``decode(data)`` == ``message.decode(data, decode_choices=False)`` (module docstring):
    the frame's signal values by name (raw numbers scaled, enums as numbers)."""

    def __init__(self, message: Message) -> None:
        self.message = message
        self.length = message.length
        codecs = message._codecs
        self._root = None if codecs is None or not _covered(message) else _compile(codecs)
        self.decode: Callable[[bytes], dict[str, Any]] = self._decode_tree
        if self._root is not None and not self._root.muxes:  # one function, made for it
            self.decode = _flat_decoder(self._root.fields, self.length)
        elif self._root is not None and _one_level(self._root):  # one function per page
            self.decode = _paged_decoder(self._root, self.length)

    def _decode_tree(self, data: bytes) -> dict[str, Any]:
        """``decode`` by the codec tree (multiplexers), or by cantools itself."""
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
         _scale(s.conversion))
        for s in node["signals"]
    )
    muxes = tuple((name, {value: _compile(sub) for value, sub in by_value.items()})
                  for name, by_value in node["multiplexers"].items())
    return _Node(fields, muxes)


def _scale(conversion: Any) -> Callable[[int, bool], Any] | None:
    """A signal's ``Field`` scale: None for an identity. An enum signal's conversion
    (``NamedSignalConversion``) decoded with ``decode_choices=False`` is the conversion it wraps
    (its ``raw_to_scaled`` calls that one's, the choices unread): that one's, written out when
    linear (ODOM_STATUS's enums: no cantools call per signal and frame)."""
    if type(conversion) is NamedSignalConversion and isinstance(
            getattr(conversion, "_conversion", None), BaseConversion):
        conversion = conversion._conversion
    return None if type(conversion) is IdentityConversion else conversion.raw_to_scaled


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


def _one_level(root: _Node) -> bool:
    """One multiplexer, among the root's signals, selecting sub-trees without multiplexers of
    their own (ODOM_STATUS's PAGE, SIM_TRUTH's PART)."""
    if len(root.muxes) != 1:
        return False
    name, by_value = root.muxes[0]
    return any(f[0] == name for f in root.fields) and not any(n.muxes for n in by_value.values())


def _paged_decoder(root: _Node, length: int) -> Callable[[bytes], dict[str, Any]]:
    """``LiveDecoder.decode`` of a message with one multiplexer (``_one_level``): its value
    (``int`` of its scaled value, as ``_decode`` selects) picks a function made for its page
    (the root's signals then the page's, as ``_decode`` orders them, each as ``_flat_decoder``
    writes it); a value the DBC does not define is ``_decode``'s ``DecodeError``."""
    name, by_value = root.muxes[0]
    _, shift, mask, sign, scale = next(f for f in root.fields if f[0] == name)
    pages = {value: _flat_decoder(root.fields + sub.fields, length)
             for value, sub in by_value.items()}
    known = sorted(by_value)

    def decode(data: bytes) -> dict[str, Any]:
        if len(data) < length:
            raise DecodeError(f"Wrong data size: {len(data)} instead of {length} bytes")
        raw = (int.from_bytes(data[:length], "little") >> shift) & mask
        if sign:
            raw = (raw ^ sign) - sign
        value = int(raw if scale is None else scale(raw, False))
        page = pages.get(value)
        if page is None:
            raise DecodeError(f"expected multiplexer id {known}, but got {value}")
        return page(data)

    return decode


def _flat_decoder(fields: tuple[Field, ...], length: int) -> Callable[[bytes], dict[str, Any]]:
    """``LiveDecoder.decode`` of a message without multiplexers, as one function made for it:
    per signal ``(word >> shift) & mask`` from the bytes it spans (``_raw_expression``), a sign
    extended as ``(raw ^ sign) - sign``, then cantools' linear conversion written out (``raw *
    scale + offset``, as ``raw_to_scaled`` computes it) or called (any other conversion)."""
    namespace: dict[str, Any] = {"DecodeError": DecodeError}
    items = [f"{field[0]!r}: {_field_expression(field, k, namespace)}"
             for k, field in enumerate(fields)]
    source = (f"def decode(data):\n"
              f"    if len(data) < {length}:\n"
              f"        raise DecodeError(f'Wrong data size: {{len(data)}} instead of {length} "
              f"bytes')\n"
              f"    return {{{', '.join(items)}}}\n")
    exec(compile(source, f"<livedecode {length} bytes>", "exec"), namespace)
    decode: Callable[[bytes], dict[str, Any]] = namespace["decode"]
    return decode


def _field_expression(field: Field, k: int, namespace: dict[str, Any]) -> str:
    """The expression of one signal's value from the frame's bytes (see ``_flat_decoder``)."""
    _, shift, mask, sign, scale = field
    raw = _raw_expression(shift, mask)
    if sign:
        raw = f"(({raw}) ^ {sign}) - {sign}"
    return _scaled(raw, scale, k, namespace)


def _raw_expression(shift: int, mask: int) -> str:
    """A little-endian field's raw value, ``(word >> shift) & mask`` of the frame read as one
    integer, from the bytes it spans: ``data[i] | data[i + 1] << 8 | ...``, shifted and masked
    only where it does not start or end on a byte. Each byte of ``bytes`` is a cached small int;
    a shift of the 64-bit word made a new int per signal (the bridge decodes every accepted
    frame of every robot)."""
    first, last = shift // 8, (shift + mask.bit_length() - 1) // 8
    raw = " | ".join(f"data[{i}] << {8 * (i - first)}" if i > first else f"data[{i}]"
                     for i in range(first, last + 1))
    offset = shift - 8 * first
    if offset:
        raw = f"({raw}) >> {offset}"
    if mask.bit_length() + offset != 8 * (last - first + 1):  # not up to its last byte's top
        raw = f"({raw}) & {mask}"
    return raw


def _scaled(raw: str, scale: Callable[[int, bool], Any] | None, k: int,
            namespace: dict[str, Any]) -> str:
    """The expression of a signal's value from its ``raw`` expression (see ``_flat_decoder``)."""
    if scale is None:
        return raw
    conversion: Any = getattr(scale, "__self__", None)
    if type(conversion) in (LinearConversion, LinearIntegerConversion) \
            and type(conversion.scale) in (int, float) and type(conversion.offset) in (int, float):
        return f"({raw}) * {conversion.scale!r} + {conversion.offset!r}"
    namespace[f"scale_{k}"] = scale
    return f"scale_{k}({raw}, False)"


def values_decoder(message: Message, names: tuple[str, ...],
                   defaults: dict[str, Any]) -> Callable[[bytes], tuple[Any, ...]]:
    """The values of the signals ``names`` of a frame of ``message``, as a tuple in that order
    (``defaults``: the value of a name the message lacks; any other missing is ``KeyError``):
    ``tuple(decode(data)[n] for n in names)`` of ``LiveDecoder.decode``, without its dict (the
    bridge's handlers of its most frequent frames take only these). A message without
    multiplexers is read by one function made for it (``_flat_decoder``'s expressions, the
    other signals not computed); any other picks them from ``LiveDecoder.decode``."""
    live = LiveDecoder(message)
    root = live._root
    by_name = {} if root is None or root.muxes else {f[0]: (k, f) for k, f in
                                                      enumerate(root.fields)}
    if root is None or root.muxes or not all(n in by_name or n in defaults for n in names):
        decode = live.decode

        def picked(data: bytes) -> tuple[Any, ...]:
            signals = decode(data)
            return tuple(signals[n] if n in signals or n not in defaults else defaults[n]
                         for n in names)

        return picked
    namespace: dict[str, Any] = {"DecodeError": DecodeError}
    items = [_field_expression(by_name[n][1], by_name[n][0], namespace) if n in by_name
             else repr(defaults[n]) for n in names]
    length = live.length
    source = (f"def values(data):\n"
              f"    if len(data) < {length}:\n"
              f"        raise DecodeError(f'Wrong data size: {{len(data)}} instead of {length} "
              f"bytes')\n"
              f"    return ({', '.join(items)},)\n")
    exec(compile(source, f"<livedecode values {message.name}>", "exec"), namespace)
    values: Callable[[bytes], tuple[Any, ...]] = namespace["values"]
    return values
