"""Where a pose frame held back on the bus was sent: the place its ENC_COUNTER is resolved from
(issue #11: a FAIL blamed a correct firmware under ``delay=0.5:150``).

A pose frame's ENC_COUNTER names the encoder frame the firmware had integrated last when it sent
it (``samples.match_encoder``: resolved against the latest accepted encoder frame before the
naming frame). A frame held back 150 ms on the bus (7.5 pose periods, 15 encoder periods) is
heard after 15 newer encoder frames: resolved from the latest of them, its 4-bit name lands on
a frame 16 after the one it named (pmir, seed 1: an ODOM_POSE_X sent at 3.521 s naming the
encoder frame of 3.51 s, heard at 3.671 s, was paired with the one of 3.67 s, and with an
on-time ODOM_POSE_Y naming that one: 47.2 mm and 195 mrad off a correct firmware). The host's
E2E takes such frames whenever the late ones run in sequence among themselves.

A frame heard after a send of its own message that came later (every frame of the message
whose CRC is right, in bus order: ``e2e_evidence.sent_times``) is known late, and its send time
is that later send's less the sends between. So is a frame that follows a known late one in
its sender's sequence (``late_sends``) and comes ``LATE_CYCLES`` or more after the time its
COUNTER step puts its send at, from that one (at the sender's cadence) or from the latest frame
heard in order (less than a COUNTER lap before it): every send after that one held back too
(seed 2: ODOM_POSE_Y 8 to 15 heard 150 ms late, after 0 to 6 as late, the last in order 7):
``sent_times`` reads each as in order (the step forward from 7), heard when sent, and its
name, resolved 15 encoder frames on, named a frame 16 after its own (28.6 mm off). A frame
heard in order whose predecessor was too keeps its place: a recorder that stamped a burst late
keeps the bus order, and the encoder frames around it are as late.

A late frame's name is resolved at its send time: against the encoder frames heard before it
(their bus position), as a frame heard in order is. Frames heard in order keep their place
(nothing changes on a log without late frames).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP, ENC_COUNTER_MASK, POSE_PERIOD_S
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import e2e_messages
from odocan.host.protocol.e2e_crc import crc8h2f_p02
from odocan.host.protocol.e2e_evidence import sent_times

LATE_CYCLES = 1.5  # a frame heard this many send periods after its COUNTER's send: held back
RUN_STEPS = 3  # a late run's next frame: at most this many sends on (the others lost)

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]


def crc_right_positions(frames: FrameArrays, decoder: BulkDecoder, name: str) -> IntArray:
    """The bus positions of ``name``'s frames of its DLC whose Profile 2 CRC is right (every
    frame of it when the DBC protects none)."""
    message = decoder.message(name)
    at = decoder.decode(frames, name)["index"].astype(np.int64)
    config = next((c for c in e2e_messages(decoder.db).values() if c.name == name), None)
    if config is None or config.data_ids is None or len(at) == 0:
        return at
    at = at[frames.dlc[at] == message.length]
    ids = np.asarray(config.data_ids, dtype=np.uint8)
    data = frames.data[at]
    ok = crc8h2f_p02(data, ids[data[:, 1] & ENC_COUNTER_MASK]) == data[:, 0]
    result: IntArray = at[ok]
    return result


def sent_places(frames: FrameArrays, decoder: BulkDecoder, name: str, index: IntArray,
                timestamp_s: FloatArray, enc_counter: IntArray,
                ) -> tuple[IntArray, IntArray, FloatArray]:
    """Per frame of ``name`` at bus positions ``index`` (times ``timestamp_s``; each with a
    right CRC): the bus position and time it was sent at. A frame heard in order keeps its
    own; a late one (module docstring) the place of the first frame stamped at or after its
    send time (the frames stamped before it were heard before it was sent); ``enc_counter``
    passed through: ``match_encoder``'s arguments in its order."""
    good = crc_right_positions(frames, decoder, name)
    if len(good) < 2 or len(index) == 0:
        return index, enc_counter, timestamp_s
    counter = (frames.data[good, 1] & ENC_COUNTER_MASK).astype(np.int64)
    late, sent = late_sends(frames.timestamp_s[good], counter, POSE_PERIOD_S)
    if not late.any():
        return index, enc_counter, timestamp_s
    k = np.minimum(np.searchsorted(good, index), len(good) - 1)
    moved = (good[k] == index) & late[k]
    if not moved.any():
        return index, enc_counter, timestamp_s
    sent_s = np.asarray(sent, dtype=np.float64)[k]
    places = np.where(moved, np.searchsorted(frames.timestamp_s, sent_s, side="left"), index)
    times = np.where(moved, sent_s, timestamp_s)
    return places.astype(np.int64), enc_counter, times.astype(np.float64)


def late_sends(timestamp_s: FloatArray, counter: IntArray,
               period_s: float) -> tuple[npt.NDArray[np.bool_], FloatArray]:
    """``sent_times`` of one periodic sender's frames (bus order), with a frame it reads in
    order taken late when the frame heard just before it was late and its send, one of
    (module docstring) ``_run_send`` and ``_top_send``, lies ``LATE_CYCLES`` or more before its
    stamp. Per frame, whether it was late and when it was sent."""
    ordered, sent = sent_times(timestamp_s, counter, period_s)
    late = ~np.asarray(ordered, dtype=bool)
    times = np.asarray(sent, dtype=np.float64)
    t, c = timestamp_s.tolist(), counter.tolist()
    top = -1  # the latest frame heard in order (-1: none yet)
    for k in range(len(late)):
        if late[k]:
            continue
        if k > 0 and late[k - 1]:
            sent_s = _run_send(t, c, times, k, period_s)
            if sent_s is None and top >= 0:
                sent_s = _top_send(t[k] - t[top], (c[k] - c[top]) & ENC_COUNTER_MASK,
                                   t[top], period_s)
            if sent_s is not None and t[k] - sent_s >= LATE_CYCLES * period_s:
                late[k], times[k] = True, sent_s
                continue
        top = k
    return late, times


def _run_send(t: list[float], c: list[int], times: FloatArray, k: int,
              period_s: float) -> float | None:
    """Frame ``k``'s send when it continues the late frame ``k - 1``'s run: heard at the
    sender's cadence after it (its COUNTER step, 1 to ``RUN_STEPS``, within half a period of
    the stamps' gap), it was sent that step after that one was; None: no run (a silence: a
    stall's first sends are on time)."""
    step = (c[k] - c[k - 1]) & ENC_COUNTER_MASK
    gap = (t[k] - t[k - 1]) / period_s
    if not 1 <= step <= RUN_STEPS or abs(gap - step) > 0.5:
        return None
    return float(times[k - 1]) + step * period_s


def _top_send(dt_s: float, step: int, top_s: float, period_s: float) -> float | None:
    """A frame's send ``step`` sends (its COUNTER step) after the latest frame heard in order,
    ``dt_s`` before it: only while that one is less than a COUNTER lap old (beyond, the step
    cannot tell the sends: after a stall's silence it read the first send late)."""
    if dt_s >= ENC_COUNTER_LAP * period_s or step == 0:
        return None
    return top_s + step * period_s
