"""The frames a re-prime at power-up took, pinned by the firmware's first count page (issue #11:
"a PASS/OK must never hide a wrong pose", and a FAIL never blames a correct firmware).

A firmware halted at its power-up long enough to re-prime (COUNTER_RESET) sends its first
ENC_E2E_OK page only after it resumed. Its ENC_E2E_LOST then holds one jump only, when the log
has no hole since the power-up: the E2E counter's step into the frame ``r`` it re-primed on
from the last frame ``f`` its FIFO kept, ``(r - f - 1) mod 16`` (the re-prime path skips the
firmware's whole-cycle addition: ``firmware/encoders.py``). It is a value the firmware counted,
not a bus time: a recorder stamping ODOM_STATUS late (tests/test_status_stamped_late.py) cannot
move it, where the page's position in the log (ENC_E2E_OK's frames) can. Given ``r`` it pins
``f``: the judges' pairs (f, r) (``stallreprime._chosen``, ``reprimereplay.replayed``) keep the
ones it allows. Before, every pair was open, and on pmir's circle moving at power-up, halted
10 s, a firmware 2 LSB off in X from its first pose after the re-prime PASSed every judge.

None of the pairs allowed (a frame lost the log does not show): the pairs stay open, as before.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.powerup import holds_first_cycle
from odocan.host.judge.samples import ENC_E2E_PAGE, Encoders, IntArray
from odocan.host.protocol.decode import BulkDecoder, DecodeError

E2E_COUNTER_VALUES = 16  # WHEEL_ENCODERS E2E COUNTER values (Profile 2: 4 bits)


def lost_allows(lost: int | None, f: int, r: int) -> bool:
    """Whether the pair (``f``, ``r``: encoder frames, the log without a hole between them)
    matches ENC_E2E_LOST ``lost`` (None: no evidence, every pair)."""
    return lost is None or (r - f - 1) % E2E_COUNTER_VALUES == lost % E2E_COUNTER_VALUES


def kept_pairs(pairs: list[tuple[int, int]], lost: int | None) -> list[tuple[int, int]]:
    """The ``pairs`` ``lost`` allows; all of them when it allows none (module docstring)."""
    kept = [(f, r) for f, r in pairs if lost_allows(lost, f, r)]
    return kept or pairs


def power_up_lost(frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder,
                  enc: Encoders, breaks: IntArray | None) -> dict[int, int]:
    """ENC_E2E_LOST of the life's first count page by the stall ``breaks`` (encoder frames the
    firmware resumed at, ``stalls.after_stalls``) it tells (module docstring): the one break
    before the page, when the frames start at the firmware's power-up (its first summary UPTIME
    0, its first ODOM_STATUS of its first cycle) and the encoder frames up to the page carry
    every COUNTER (no hole). Empty when not proven."""
    if breaks is None or not len(breaks) or not len(enc.seq):
        return {}
    try:
        status = decoder.decode(frames, "ODOM_STATUS")
        summary = decoder.decode_page(frames, "ODOM_STATUS", 0)
        page = decoder.decode_page(frames, "ODOM_STATUS", ENC_E2E_PAGE)
    except DecodeError:
        return {}
    if "COUNTER" not in status or "UPTIME" not in summary or "ENC_E2E_LOST" not in page:
        return {}
    keep, uptime = accepted[page["index"]], summary["UPTIME"][accepted[summary["index"]]]
    counters = status["COUNTER"][accepted[status["index"]]]
    if not keep.any() or not len(uptime) or int(uptime[0]) != 0 \
            or not holds_first_cycle(int(counters[0])):
        return {}
    at = int(page["index"][keep][0])
    before = int(np.searchsorted(enc.index, at))  # encoder frames before the page
    stalls = [b for b in breaks.tolist() if 0 < b < before]
    if len(stalls) != 1 or np.any(np.diff(enc.seq[: before + 1]) != 1):
        return {}
    return {int(stalls[0]): int(page["ENC_E2E_LOST"][keep][0])}
