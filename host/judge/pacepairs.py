"""The one-step intervals of a bus's encoder frames, in whichever order they came
(``host.judge.livepace`` measures the bus's pace from them).

A live bus that delays frames reorders them (``--faults delay=0.5:20``: a frame held two periods,
heard behind the next two). Pairing each frame only with the one heard just before it, when one
COUNTER step behind, keeps the long intervals and leaves the short ones out: a frame held behind
the next is paired with neither, the pair after it is, 30 ms apart. The mean came to 14.4 ms, a
pace of 0.696, and ``livepace`` took a live bus for a replay at ``--speed 0.7`` (issue #11: the
monitor then said POSE WRONG, 84 and 194 mm, on a correct firmware the bridge and ``analyze``
passed).

``EncoderPairs`` places each CRC-right frame on an unwrapped sequence: its COUNTER's step from
the frame furthest ahead, read as up to ``BEHIND`` periods behind it (a frame held back) or ahead
(a frame lost or a silence), a lap further ahead when that slot was heard already with another
payload (a silence of 9 to 16 periods); the same payload again is a repetition, not used. A frame
closes the pair with each sequence neighbour heard before it: ``t - t_before`` (>= 0) and
``t_after - t`` (<= 0, heard out of order), each pair once. The intervals of consecutive pairs
sum to their span, whatever the order the frames came in, so their mean is the period's
(``delay=0.5:20`` at 1x: 10.0 ms, at ``--speed 2``: 5.0 ms). A pair whose earlier-heard frame
is stamped later is none (the clock went back: a replay restarted). A frame held back more than
``BEHIND`` periods is read ahead (15 behind is one ahead to a 4-bit COUNTER): ``delay=0.5:150``
reads 1.27x; ``livepace`` then also asks the frames heard in order."""

from __future__ import annotations

from odocan.host.protocol.busfacts import ENC_COUNTER_LAP, ENC_COUNTER_MASK

BEHIND = 7  # periods a frame may come behind the one furthest ahead (a delay up to 70 ms)


class EncoderPairs:
    """The encoder frames heard within a lap of the one furthest ahead, by unwrapped sequence
    (module docstring); ``intervals`` per CRC-right frame."""

    def __init__(self) -> None:
        self._head: tuple[int, int] | None = None  # (sequence, COUNTER) of the furthest ahead
        self._heard: dict[int, tuple[float, bytes]] = {}  # sequence: (bus time s, payload)

    def intervals(self, t_s: float, counter: int, data: bytes) -> list[float]:
        """The one-step intervals (s) the frame heard at ``t_s`` closes (none: a repetition)."""
        seq = self._sequence(counter, data)
        if seq is None:
            return []
        self._heard[seq] = (t_s, data)
        out = []
        before, after = self._heard.get(seq - 1), self._heard.get(seq + 1)
        if before is not None and before[0] <= t_s:
            out.append(t_s - before[0])
        if after is not None and after[0] <= t_s:
            out.append(after[0] - t_s)
        return out

    def _sequence(self, counter: int, data: bytes) -> int | None:
        """The frame's unwrapped sequence (the head moved on when it is ahead), None for a
        repetition of a frame heard."""
        if self._head is None:
            self._head = (0, counter)
            return 0
        head_seq, head_counter = self._head
        seq = head_seq + ((counter - head_counter + BEHIND) & ENC_COUNTER_MASK) - BEHIND
        heard = self._heard.get(seq)
        if heard is not None:
            if heard[1] == data:
                return None
            seq += ENC_COUNTER_LAP  # that slot's frame was another: a lap on, after a silence
        if seq > head_seq:
            self._head = (seq, counter)
            self._heard = {s: v for s, v in self._heard.items() if s > seq - ENC_COUNTER_LAP}
        return seq
