"""Hand edits of a recorded log, as a skeptical user makes them: a signal's raw value raised by
some LSB from a time on, each edited frame re-signed with its Profile 2 CRC by cantools (not by
odocan's own E2E code), every other frame copied as recorded."""

from __future__ import annotations

from pathlib import Path

import can
import cantools
from cantools.autosar import compute_profile2_crc
from cantools.database.can import Database

from odocan.sim import contract
from tests.dbc_typed import dbc_attribute


def raise_raw(src: Path, dst: Path, message: str, byte_span: tuple[int, int], lsb: int,
              from_s: float, until_s: float = float("inf"), wrap: bool = False) -> int:
    """Copy ``src`` to ``dst`` with the little-endian signed raw field in bytes
    ``byte_span`` (start, length) of ``message`` raised by ``lsb`` from ``from_s`` s after the
    log's first frame on (up to ``until_s``, excluded); the number of frames changed.
    ``wrap``: the field wraps round its width (a binary angle: HEADING near pi)."""
    db = cantools.database.load_file(str(contract.DBC_PATH))
    assert isinstance(db, Database)
    target = db.get_message_by_name(message)
    ids = [int(v) for v in dbc_attribute(target, "E2EDataIDs").split(",")]
    changed, first = 0, None
    with can.Logger(str(dst)) as out:
        for msg in can.LogReader(str(src)):
            first = msg.timestamp if first is None else first
            if msg.arbitration_id == target.frame_id and from_s <= msg.timestamp - first < until_s:
                msg.data = _raised(msg.data, byte_span, lsb, ids, wrap)
                changed += 1
            out.on_message_received(msg)
    return changed


def _raised(payload: bytes | bytearray, byte_span: tuple[int, int], lsb: int,
            ids: list[int], wrap: bool = False) -> bytearray:
    """``payload`` with the signed little-endian field at ``byte_span`` raised by ``lsb`` (round
    its width when ``wrap``) and its E2E Profile 2 CRC recomputed (the Data ID its COUNTER
    selects from ``ids``)."""
    data, (start, length) = bytearray(payload), byte_span
    raw = int.from_bytes(data[start:start + length], "little", signed=True) + lsb
    half = 1 << (8 * length - 1)
    raw = (raw + half) % (2 * half) - half if wrap else raw
    data[start:start + length] = raw.to_bytes(length, "little", signed=True)
    crc = compute_profile2_crc(bytes(data), ids[data[1] & 0xF])
    assert crc is not None
    data[0] = crc
    return data


def raise_raw_once(src: Path, dst: Path, message: str, byte_span: tuple[int, int], lsb: int,
                   from_s: float, count: int = 1) -> list[float]:
    """As ``raise_raw`` but only on the first ``count`` frames of ``message`` at or after
    ``from_s`` s; the (relative) times of the frames changed."""
    db = cantools.database.load_file(str(contract.DBC_PATH))
    assert isinstance(db, Database)
    target = db.get_message_by_name(message)
    ids = [int(v) for v in dbc_attribute(target, "E2EDataIDs").split(",")]
    changed: list[float] = []
    first = None
    with can.Logger(str(dst)) as out:
        for msg in can.LogReader(str(src)):
            first = msg.timestamp if first is None else first
            if (msg.arbitration_id == target.frame_id and msg.timestamp - first >= from_s
                    and len(changed) < count):
                msg.data = _raised(msg.data, byte_span, lsb, ids)
                changed.append(msg.timestamp - first)
            out.on_message_received(msg)
    return changed


def drop_frames(src: Path, dst: Path, messages: tuple[str, ...], from_s: float,
                to_s: float) -> int:
    """Copy ``src`` to ``dst`` without the frames of ``messages`` whose time after the log's
    first frame lies in [from_s, to_s): the firmware's output fallen silent; the number dropped."""
    db = cantools.database.load_file(str(contract.DBC_PATH))
    assert isinstance(db, Database)
    ids = {db.get_message_by_name(name).frame_id for name in messages}
    dropped, first = 0, None
    with can.Logger(str(dst)) as out:
        for msg in can.LogReader(str(src)):
            first = msg.timestamp if first is None else first
            if msg.arbitration_id in ids and from_s <= msg.timestamp - first < to_s:
                dropped += 1
                continue
            out.on_message_received(msg)
    return dropped
