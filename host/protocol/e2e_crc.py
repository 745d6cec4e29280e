"""The CRC of AUTOSAR E2E Profile 2 on the host (``host.protocol.e2e``): CRC8H2F (polynomial
0x2F, initial value 0xFF, final XOR 0xFF) over bytes 1..7 and then the data ID, over a whole log
(numpy, two bytes a lookup) or one frame (live). Moved out of ``host.protocol.e2e`` (at its 500
lines), which re-exports it."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

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


def _pair_tables() -> tuple[npt.NDArray[np.uint8], ...]:
    """CRC8H2F is linear in its register and bytes: the register after the 8 bytes of Profile 2
    (bytes 1..7, the data ID) is ``_CRC_ZEROS`` (those of zero bytes) XOR each byte's own
    contribution at its place. These 4 tables (65536 entries) give the contributions of two
    neighbouring places at once, indexed by the two bytes as one little-endian uint16."""
    byte = np.arange(256)
    places = []
    for place in range(P02_LENGTH):
        register = CRC8H2F_TABLE[byte]
        for _ in range(place + 1, P02_LENGTH):
            register = CRC8H2F_TABLE[register]
        places.append(register)
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


def crc8h2f_p02_one(data: bytes, data_id: int) -> int:
    """The same for one frame of ``P02_LENGTH`` bytes (live monitoring, per frame of every robot:
    the eight lookups written out, no loop; callers check the length first)."""
    t = _TABLE_LIST
    return int(t[t[t[t[t[t[t[t[CRC8H2F_INIT ^ data[1]] ^ data[2]] ^ data[3]] ^ data[4]]
                       ^ data[5]] ^ data[6]] ^ data[7]] ^ data_id] ^ CRC8H2F_XOR_OUT)
