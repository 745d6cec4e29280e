"""The encoder frames a replay feeds, and the tick of each (``host.judge.replay``'s input).

A log's accepted WHEEL_ENCODERS frames are numbered by the sender's period: the E2E COUNTER's
steps mod 16, widened by 16 where the timestamps say that many periods passed (as
``host.judge.analysis`` does); gaps longer than ``MAX_GAP_TICKS`` are shortened to it. A pose
frame names its encoder frame by ENC_COUNTER, resolved with the judges' age rule
(``samples.named_targets``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge import gapseen
from odocan.host.judge.samples import Encoders, contract_cycle_s, named_targets
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP as LAP
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK
from odocan.host.protocol.decode import BulkDecoder
from odocan.sim import contract
from odocan.sim.board import TICK_S, TX_LATENCY_S

IntArray = npt.NDArray[np.int64]
MAX_GAP_TICKS = 6000  # a gap in the log longer than 60 s is replayed as 60 s


@dataclass(frozen=True)
class EncoderTrack:
    """The accepted WHEEL_ENCODERS frames of a FrameArrays and the tick of each."""

    index: IntArray  # positions in the frames
    counter: IntArray  # E2E COUNTER
    tick: IntArray  # 10 ms periods since the first one, strictly increasing
    timestamp_s: npt.NDArray[np.float64]  # bus times
    cycle_s: float | None  # the DBC cycle time

    @classmethod
    def of(cls, frames: FrameArrays, accepted: npt.NDArray[np.bool_],
           decoder: BulkDecoder) -> EncoderTrack:
        """The track of ``frames`` (empty when none is accepted)."""
        enc = decoder.decode(frames, "WHEEL_ENCODERS")
        keep = accepted[enc["index"]]
        counter = enc["COUNTER"][keep].astype(np.int64)
        ticks = encoder_ticks(enc["timestamp_s"][keep], counter)
        return cls(enc["index"][keep], counter, ticks, enc["timestamp_s"][keep],
                   contract_cycle_s(decoder, "WHEEL_ENCODERS"))

    def named(self, index: IntArray, enc_counter: IntArray,
              timestamp_s: npt.NDArray[np.float64]) -> IntArray:
        """The tick of the encoder frame that frames at ``index`` (sent at ``timestamp_s``)
        name by ``enc_counter``, resolved against the latest accepted encoder frame before each
        when it is less than 8 cycles older (``samples.named_targets``, the judges' rule: across
        a longer gap of the log the 4-bit COUNTER cannot tell the frame named from one 16
        periods away); -1 when that frame is not in the track or comes after the naming frame
        in the log (``samples.match_encoder``'s causal rule: no firmware names a frame it has not
        yet taken). Without it, the first pose after a halt of 30, 46 or 62 ticks (14 mod 16),
        naming the encoder frame of the halt's first tick that the board's receive FIFO held,
        resolved 32 ticks later, to the frame of the same COUNTER just after the halt, and was
        compared, as a resend, with the different pose truly naming that one: a correct
        firmware's replay, byte-identical, departed by up to 345.6 mrad and was UNJUDGED."""
        result = np.full(len(index), -1, dtype=np.int64)
        if len(self.tick) == 0:
            return result
        none = np.zeros(len(self.tick), dtype=np.int64)
        as_encoders = Encoders(index=self.index, counter=self.counter, seq=self.tick, left=none,
                               right=none, timestamp_s=self.timestamp_s, cycle_s=self.cycle_s)
        has, target = named_targets(as_encoders, index, enc_counter, timestamp_s)
        target = target[has]
        found = np.minimum(np.searchsorted(self.tick, target), len(self.tick) - 1)
        taken = self.index[found] < index[has]  # named before it was on the bus: none
        result[has] = np.where((self.tick[found] == target) & taken, target, -1)
        return result


def encoder_ticks(timestamp_s: npt.NDArray[np.float64], counter: IntArray) -> IntArray:
    """The sender's period of each frame: COUNTER steps mod 16, widened by 16 where the
    timestamps say that many periods passed; gaps capped at ``MAX_GAP_TICKS``. A step of 0 is
    a whole lap (the host's check accepts a same COUNTER only as 16 * k periods on), not 1:
    pmir straight 635, 9 s, ``busoff=2.6:0.3``, 0.32 s without a frame were numbered 33
    periods, every pose after them one tick off the firmware's, and the replay's pose phase,
    voted by the longer part after, named none of the log's poses (UNJUDGED)."""
    if len(counter) == 0:
        return np.zeros(0, dtype=np.int64)
    step = ((np.diff(counter) - 1) & ENC_COUNTER_MASK).astype(np.int64) + 1
    periods = np.rint(np.diff(timestamp_s) / contract.cycle_time_s("WHEEL_ENCODERS"))
    step += LAP * np.maximum(0, np.rint((periods - step) / LAP)).astype(np.int64)
    step = np.clip(step, 1, MAX_GAP_TICKS)
    return np.concatenate(([0], np.cumsum(step))).astype(np.int64)


def late_frames(frames: FrameArrays, accepted: npt.NDArray[np.bool_],
                track: EncoderTrack) -> tuple[IntArray, IntArray]:
    """The WHEEL_ENCODERS frames of ``frames`` the host's E2E check refused (late, repeated,
    corrupt: the recording firmware's own check took some of them, a late one in particular)
    after the track's first, and the tick at which each reached the firmware: a frame on the bus
    at log time T was in the firmware's receive FIFO at the first tick whose start plus the
    board's ``TX_LATENCY_S`` is at or past T (``sim.rig``: held frames due by then go on the bus
    before the board's tick), counted from the accepted frame before it and kept between that
    one's tick and the next's. The replay feeds them too, in log order, and the replayed
    firmware's E2E check decides, as the recording one's did: fed the accepted frames alone, a
    correct firmware replayed ``delay=0.3:50`` (1235 of 2000 frames fed) 0.942 mm off."""
    encoder_id = contract.database().get_message_by_name("WHEEL_ENCODERS").frame_id
    positions = np.flatnonzero((frames.can_id == encoder_id) & ~accepted).astype(np.int64)
    if len(track.index) == 0 or len(positions) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    positions = positions[positions > track.index[0]]
    before = np.searchsorted(track.index, positions) - 1
    after_s = np.asarray(frames.timestamp_s, dtype=np.float64)[positions] \
        - track.timestamp_s[before] - TX_LATENCY_S
    ticks = track.tick[before] + np.maximum(0, np.ceil(np.round(after_s / TICK_S, 6)))
    nxt = np.minimum(before + 1, len(track.tick) - 1)
    ticks = np.where(before + 1 < len(track.tick), np.minimum(ticks, track.tick[nxt]), ticks)
    return positions, ticks.astype(np.int64)


def crc_holds(frames: FrameArrays, decoder: BulkDecoder, name: str,
              rows: IntArray) -> npt.NDArray[np.bool_]:
    """Which frames of message ``name`` at ``rows`` carry a right Profile 2 CRC, whatever their
    sequence (``gapseen.crc_holds``): a pose the firmware sent is one to compare with the
    replay's, even where the host's E2E window refused it (the first two after a reboot, whose
    COUNTER starts again at 0: left out, a pose raised 10 m there PASSed the replay)."""
    return gapseen.crc_holds(frames, decoder, rows, name)
