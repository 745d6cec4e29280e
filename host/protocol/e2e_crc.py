"""The CRC of AUTOSAR E2E Profile 2 (CRC8H2F: polynomial 0x2F, initial value 0xFF, final XOR
0xFF, over bytes 1..7 then the frame's data ID), over a whole log at once and for one frame
(``host.protocol.e2e``, which re-exports these names)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from odocan.host.protocol.busfacts import ENC_COUNTER_MASK as MASK

CRC8H2F_POLY = 0x2F
CRC8H2F_INIT = 0xFF
CRC8H2F_XOR_OUT = 0xFF
P02_LENGTH = 8  # bytes: Profile 2 over classic CAN frames


def _crc_table() -> npt.NDArray[np.uint8]:
    """The MSB-first CRC8H2F table (256 entries), built with numpy: 8 shift/xor rounds."""
    crc: npt.NDArray[np.int64] = np.arange(256, dtype=np.int64)
    for _ in range(8):
        crc = np.where(crc & 0x80, (crc << 1) ^ CRC8H2F_POLY, crc << 1) & 0xFF
    return crc.astype(np.uint8)


CRC8H2F_TABLE = _crc_table()
_TABLE_LIST = CRC8H2F_TABLE.tolist()


def _places() -> list[npt.NDArray[np.uint8]]:
    """Each place's contribution to the register after the 8 bytes of Profile 2 (place 0: byte
    1, ..., place 6: byte 7, place 7: the data ID), by the byte there (256 entries each)."""
    byte = np.arange(256)
    places = []
    for place in range(P02_LENGTH):
        register = CRC8H2F_TABLE[byte]
        for _ in range(place + 1, P02_LENGTH):
            register = CRC8H2F_TABLE[register]
        places.append(register)
    return places


def _pair_tables() -> tuple[npt.NDArray[np.uint8], ...]:
    """CRC8H2F is linear in its register and bytes: the register after the 8 bytes of Profile 2
    (bytes 1..7, the data ID) is ``_CRC_ZEROS`` (those of zero bytes) XOR each byte's own
    contribution at its place (``_places``). These 4 tables (65536 entries) give the
    contributions of two neighbouring places at once, indexed by the two bytes as one
    little-endian uint16."""
    places = _places()
    return tuple(
        np.bitwise_xor.outer(places[2 * k + 1], places[2 * k]).ravel() for k in range(4)
    )


def _crc_of_zeros() -> int:
    register = CRC8H2F_INIT
    for _ in range(P02_LENGTH):
        register = int(CRC8H2F_TABLE[register])
    return register


_CRC_PAIRS = _pair_tables()
_CRC_ZEROS = _crc_of_zeros() ^ CRC8H2F_XOR_OUT
_U16_LE = np.dtype("<u2")


def crc8h2f_p02(
    data: npt.NDArray[np.uint8], data_ids: npt.NDArray[np.uint8]
) -> npt.NDArray[np.uint8]:
    """Profile 2 CRCs of N 8-byte frames: CRC8H2F over bytes 1..7 then each frame's data ID
    (four lookups a frame in ``_CRC_PAIRS``: bytes 1-2, 3-4, 5-6 read in place as uint16)."""
    data = np.ascontiguousarray(data, dtype=np.uint8)
    if data.shape[0] == 0:
        return np.zeros(0, dtype=np.uint8)
    pairs = np.ndarray((data.shape[0], 3), dtype=_U16_LE, buffer=data, offset=1, strides=(8, 2))
    last = data[:, 7].astype(np.uint16) | (data_ids.astype(np.uint16) << 8)
    crc = np.take(_CRC_PAIRS[3], last) ^ np.uint8(_CRC_ZEROS)
    for k in range(3):
        crc ^= np.take(_CRC_PAIRS[k], pairs[:, k])
    result: npt.NDArray[np.uint8] = crc
    return result


_PLACES: list[list[int]] = [place.tolist() for place in _places()]
# The check by place (``byte1_table``): bytes 2..7's contributions, shared by every message
PLACE_B2, PLACE_B3, PLACE_B4, PLACE_B5, PLACE_B6, PLACE_B7 = _PLACES[1:7]
_BYTE1_TABLES: dict[tuple[int, ...], list[int]] = {}


def byte1_table(data_ids: tuple[int, ...]) -> list[int]:
    """The first table of the Profile 2 check by place: a frame's CRC is right exactly when
    ``table[data[1]] ^ PLACE_B2[data[2]] ^ ... ^ PLACE_B7[data[7]] == data[0]``
    (``crc_right_by_place``). CRC8H2F is linear (``_pair_tables``): byte 1's contribution XOR
    that of the data ID its COUNTER (byte 1's low nibble) selects XOR the register of zero
    bytes and the final XOR, by byte 1; the ``PLACE_B*`` tables those of bytes 2..7. Seven
    lookups of one byte each a frame, no nesting and no call (the live check, per frame of
    every robot: ``crc8h2f_p02_one`` and its call cost a third more; 256-entry tables stay in
    the cache, and a byte of ``bytes`` is a cached small int where a shifted 64-bit word is a
    new object). One table per list of data IDs, shared."""
    table = _BYTE1_TABLES.get(data_ids)
    if table is None:
        byte1, data_id = _PLACES[0], _PLACES[7]
        table = _BYTE1_TABLES[data_ids] = [byte1[b1] ^ data_id[data_ids[b1 & MASK]] ^ _CRC_ZEROS
                                           for b1 in range(256)]
    return table


def crc_right_by_place(data: bytes, data_ids: tuple[int, ...]) -> bool:
    """Whether the CRC of an 8-byte frame is right, by ``byte1_table``'s tables (as the live
    check reads them, written out there; tests hold this to cantools)."""
    return (byte1_table(data_ids)[data[1]] ^ PLACE_B2[data[2]] ^ PLACE_B3[data[3]]
            ^ PLACE_B4[data[4]] ^ PLACE_B5[data[5]] ^ PLACE_B6[data[6]]
            ^ PLACE_B7[data[7]]) == data[0]


def crc8h2f_p02_one(data: bytes, data_id: int) -> int:
    """The same for one frame of ``P02_LENGTH`` bytes (live monitoring, per frame of every robot:
    the eight lookups written out, no loop; callers check the length first)."""
    t = _TABLE_LIST
    return int(t[t[t[t[t[t[t[t[CRC8H2F_INIT ^ data[1]] ^ data[2]] ^ data[3]] ^ data[4]]
                       ^ data[5]] ^ data[6]] ^ data[7]] ^ data_id] ^ CRC8H2F_XOR_OUT)
