"""The CRC of AUTOSAR E2E Profile 2 (CRC8H2F: polynomial 0x2F, initial value 0xFF, final XOR
0xFF, over bytes 1..7 then the frame's data ID), over a whole log at once and for one frame
(``host.protocol.e2e``, which re-exports these names)."""

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


def _word_pair(low: list[int], high: list[int]) -> list[int]:
    """The contributions of two neighbouring bytes at once, indexed by them as one
    little-endian uint16 (``low`` the first byte's, ``high`` the second's)."""
    return [lo ^ hi for hi in high for lo in low]


_PLACES = [place.tolist() for place in _places()]
# The word form of the check (``word_head``): bytes 2-3, 4-5 and 6-7's contributions, shared
WORD_B23, WORD_B45, WORD_B67 = (_word_pair(_PLACES[k], _PLACES[k + 1]) for k in (1, 3, 5))
_WORD_HEADS: dict[tuple[int, ...], list[int]] = {}


def word_head(data_ids: tuple[int, ...]) -> list[int]:
    """The first table of the Profile 2 check by table over a frame read as one little-endian
    integer ``w`` (``int.from_bytes(data, "little")`` of its 8 bytes): its CRC is right exactly
    when ``head[w & 0xFFFF] ^ WORD_B23[(w >> 16) & 0xFFFF] ^ WORD_B45[(w >> 32) & 0xFFFF] ^
    WORD_B67[w >> 48]`` is 0 (``crc_right_by_word``). CRC8H2F is linear (``_pair_tables``):
    ``head``, indexed by bytes 0-1, holds the CRC byte itself XOR byte 1's contribution XOR that
    of the data ID its COUNTER (byte 1's low nibble) selects XOR the register of zero bytes and
    the final XOR; the ``WORD_B*`` tables the contributions of bytes 2-3, 4-5, 6-7. Four
    lookups a frame, not ``crc8h2f_p02_one``'s eight and its call (the live check, per frame of
    every robot). One table per list of data IDs, shared (65536 entries)."""
    head = _WORD_HEADS.get(data_ids)
    if head is None:
        byte1, data_id = _PLACES[0], _PLACES[7]
        head = _WORD_HEADS[data_ids] = [
            crc ^ byte1[b1] ^ data_id[data_ids[b1 & 0xF]] ^ _CRC_ZEROS
            for b1 in range(256) for crc in range(256)]
    return head


def crc_right_by_word(data: bytes, data_ids: tuple[int, ...]) -> bool:
    """Whether the CRC of an 8-byte frame is right, by ``word_head``'s tables (as the live
    check reads them, written out there; tests hold this to ``crc8h2f_p02_one``)."""
    w = int.from_bytes(data, "little")
    return not (word_head(data_ids)[w & 0xFFFF] ^ WORD_B23[(w >> 16) & 0xFFFF]
                ^ WORD_B45[(w >> 32) & 0xFFFF] ^ WORD_B67[w >> 48])


def crc8h2f_p02_one(data: bytes, data_id: int) -> int:
    """The same for one frame of ``P02_LENGTH`` bytes (live monitoring, per frame of every robot:
    the eight lookups written out, no loop; callers check the length first)."""
    t = _TABLE_LIST
    return int(t[t[t[t[t[t[t[t[CRC8H2F_INIT ^ data[1]] ^ data[2]] ^ data[3]] ^ data[4]]
                       ^ data[5]] ^ data[6]] ^ data[7]] ^ data_id] ^ CRC8H2F_XOR_OUT)
