"""A ``.blf``'s top-level objects, walked by their headers: the first one python-can cannot take
frames from (issue #11).

``can.BLFReader`` takes frames only from log containers (object type 10) compressed by a method it
knows (0 none, 2 zlib); another top-level object, or a container of another method, it skips
(the latter with a ``logging`` warning), so a ``.blf`` whose first container header is corrupt
read as "empty log". The walk reads 16 + 16 bytes per container (a 10 GB log has ~80 000
containers) and says where the file stops being a BLF python-can reads. A container whose
compressed data is corrupt is the reader's own error (zlib's), and a file cut short
``logs.blf_warning``'s: neither is looked at here.
"""

from __future__ import annotations

import logging
import struct
from pathlib import Path
from typing import BinaryIO

_FILE_SIGNATURE = b"LOGG"
_OBJECT = struct.Struct("<4sHHLL")  # signature "LOBJ", header size, header version, size, type
_CONTAINER = struct.Struct("<H6xL4x")  # compression method, uncompressed size
_LOG_CONTAINER = 10
_METHODS = (0, 2)  # none, zlib deflate: the methods python-can reads


def blf_corruption(path: Path) -> str | None:
    """Where ``path`` (a ``.blf``) stops holding frames python-can reads, in words (``object at
    byte 144: no LOBJ signature``), or None when every top-level object is a container it
    reads (or the file cannot be opened: the reader says that)."""
    try:
        with path.open("rb") as file:
            return _walk(file)
    except OSError:
        return None


def _walk(file: BinaryIO) -> str | None:
    head = file.read(8)
    if len(head) < 8 or head[:4] != _FILE_SIGNATURE:
        return "no BLF file signature (LOGG) at byte 0"
    position_b = int.from_bytes(head[4:8], "little")  # the file header's size
    file.seek(position_b)
    while len(header := file.read(_OBJECT.size)) == _OBJECT.size:
        signature, _, _, size_b, kind = _OBJECT.unpack(header)
        where = f"object at byte {position_b}"
        if signature != b"LOBJ":
            return f"{where}: no object signature (LOBJ)"
        if size_b < _OBJECT.size + _CONTAINER.size:
            return f"{where}: object size {size_b} bytes, shorter than a container's header"
        if kind != _LOG_CONTAINER:
            return f"{where}: object type {kind}, not a log container (10)"
        container = file.read(_CONTAINER.size)
        if len(container) < _CONTAINER.size:
            return None  # cut short: blf_warning's
        method = _CONTAINER.unpack(container)[0]
        if method not in _METHODS:
            return f"{where}: compression method {method}, unknown (0 none, 2 zlib)"
        position_b += size_b + size_b % 4  # python-can's padding rule
        file.seek(position_b)
    return None


class _SaidByTheWalk(logging.Filter):
    """Drops python-can's "Unknown compression method" record: ``blf_corruption`` says it,
    with the byte, in the one line of an error or a warning."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not record.getMessage().startswith("Unknown compression method")


_FILTER = _SaidByTheWalk()


def quiet_python_can_blf() -> None:
    """Install the filter on python-can's BLF logger (once; idempotent)."""
    logger = logging.getLogger("can.io.blf")
    if _FILTER not in logger.filters:
        logger.addFilter(_FILTER)
