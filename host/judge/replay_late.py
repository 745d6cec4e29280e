"""Where a late pose frame of a log was sent, to name its encoder frame from there
(``replay_compare.halves_by_tick``'s naming; issue #11).

A pose frame names the encoder frame its firmware last took by a 4-bit ENC_COUNTER, which the
judges resolve against the latest accepted encoder frame logged before the pose, within half a
COUNTER lap (``EncoderTrack.named``). A bus that delays frames logs a pose frame late: delayed
by 8 to 16 encoder periods, its ENC_COUNTER resolves a lap off. The replay compares every pose
its firmware sent with a right CRC (``replay_track.crc_holds``: a reboot's first two too), so a
late one was compared with the replayed pose of a frame 16 periods later:

* kobuki random 700, 8 s, ``busoff=1.5:0.2,delay=0.1:150,stall=3.1:0.3`` (run and analyze
  PASS): ODOM_POSE_X of 4.281 s (COUNTER 7, ENC_COUNTER 11) logged 150 ms late at 4.431 s
  named the frame of 4.43 s instead of 4.27 s; the replayed firmware, its stall halted right
  and every encoder frame taken as the recording one took it, was byte-identical to the log,
  yet "departed" by 156 mrad and 11.7 mm at 3 such frames, and the stall's fit kept a halt a
  tick early (277 of 301 poses identical, not 298): UNJUDGED.

A late frame is known by its own E2E COUNTER: one whose COUNTER lies ``MIN_BEHIND`` to
``MAX_BEHIND`` sends behind that of the latest frame of its message sent on (the head: each
frame whose COUNTER steps forward by up to ``MIN_BEHIND``, or by up to ``HALF_LAP`` no faster
than the pose period allows), or seems to step forward by more than ``MIN_BEHIND`` sooner than
that (a frame ``HALF_LAP`` to 11 sends late, 150 to 220 ms: kobuki square 841, 9 s,
``delay=0.1:200``, 54 of 450 ODOM_POSE_X 10 sends late, their COUNTER 6 ahead, named a lap off
from where they were logged: the correct firmware's replay FAILed by 48 mm), logged less than
``MAX_BEHIND + 1`` pose periods after it (a firmware that lost whole sends in a bus-off or a
stall steps *forward*, and its silence lasted longer), with no boot summary (``boot_summaries``:
a new firmware's COUNTER starts again at 0) between the two. It was sent as
many pose periods before the head as it is behind it, and is named from the latest accepted
encoder frame logged by then. The host's E2E verdict is no head: under ``delay=0.3:50`` (pmir
circle 20) it took 350 of 1000 ODOM_POSE_X frames, and a frame 130 ms after the last of them was
read as late (``tests/test_replay_trust.py``). Less late than ``MIN_BEHIND`` sends, a frame is
named where it was logged, as before: its name resolves right there.

A firmware that falls silent (a reboot) leaves its head stale: the frames it sent just before,
held back 200 ms, come after it with no frame sent on between. Kobuki random 911 and pmir
figure8 912, 9 s, ``reboot=1.5:0.3,delay=0.1:200`` (run and analyze PASS), the firmware off at
1.5 s: an ODOM_POSE_X of COUNTER 8 sent at 1.441 s and logged at 1.641 s, 160 ms after the head
(COUNTER 10, 1.481 s), was read as one after a silence though a step forward of 14 sends
cannot come in 8 periods; an ODOM_POSE_Y 3 sends behind its head but logged 140 ms after it
was named where it was logged (fewer than ``MIN_BEHIND`` sends behind); and an ODOM_POSE_Y of
COUNTER 10 sent at 1.481 s, a step of one from its head (1.461 s) but logged 220 ms after it,
was read as one after a silence. Each was named 16 to 20 encoder periods on, its partner half
where it was sent, and the correct firmware's replay FAILed by 67.5 and 87.9 mrad in life 0.
A frame after a silence is now one only when a step forward that long fits in the time since
its head; a frame behind it is named from its sending when that was ``MIN_BEHIND`` periods or
more before it was logged, however few sends behind; and a frame after a silence whose partner
half (the other message, same COUNTER and ENC_COUNTER: the firmware sends both halves of a pose
at one tick) was sent where the COUNTER step from the head puts it, less than a COUNTER lap
before, is named from that send (``halves_sent_at``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.reboots import boot_summaries as reboot_summaries
from odocan.host.judge.replay_track import EncoderTrack
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP, ENC_COUNTER_MASK
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.sim import contract

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]
MAX_BEHIND = 7  # sends behind the latest: below half the 4-bit COUNTER's lap, never ambiguous
MIN_BEHIND = 4  # sends behind (80 ms): less late, the name resolves right where it was logged
HALF_LAP = ENC_COUNTER_LAP // 2  # 8: half the 4-bit COUNTER's lap


def boot_summaries(frames: FrameArrays, decoder: BulkDecoder) -> IntArray:
    """The log positions of the ODOM_STATUS summaries that start a new firmware
    (``reboots.boot_summaries``: UPTIME going back, told from a summary held back by the bus).
    Not every summary at UPTIME 0: UPTIME counts whole seconds, so each summary of a life's
    first second says 0. Read as boots, they made the pose frame logged after each the head
    (``sent_at``) even when it was a late one: kobuki random 840, 9 s, ``delay=0.1:200``, the
    ODOM_POSE_Y of 0.101 s logged at 0.301 s became the head, the on-time frames after it read
    as 11 sends late and named a lap early, and the correct firmware's replay FAILed by 15.1 mm
    between gaps."""
    return np.array([b[0] for b in reboot_summaries(frames, decoder)], dtype=np.int64)


@dataclass(frozen=True)
class Partner:
    """The other half's frames of the poses a message's frames carry (``ODOM_POSE_Y`` for
    ``ODOM_POSE_X``, and back; the firmware sends both of a pose at one tick with one E2E
    COUNTER and one ENC_COUNTER): log positions, COUNTER, ENC_COUNTER and the bus time each was
    sent at (``sent_at``'s reading of its own message)."""

    rows: IntArray
    counter: IntArray
    enc_counter: IntArray
    sent_s: FloatArray


def sent_at(frames: FrameArrays, track: EncoderTrack, rows: IntArray, counter: IntArray,
            boots: IntArray, enc_counter: IntArray | None = None,
            partner: Partner | None = None) -> tuple[IntArray, FloatArray]:
    """The log position and bus time each pose frame at ``rows`` (one message, log order, its
    E2E ``counter``, ``enc_counter``) names its encoder frame from: its own, or a late one's
    sending (module docstring); a frame after a silence of its message whose ``partner`` was
    sent long before it, from that send (``_partner_sent_s``)."""
    times = np.asarray(frames.timestamp_s, dtype=np.float64)
    at, at_s = rows.astype(np.int64).copy(), times[rows].copy()
    period_s = contract.cycle_time_s("ODOM_POSE_X")
    head: int | None = None  # the latest frame of the message sent on (its number in rows)
    for k in range(len(rows)):
        if head is None:
            head = k
            continue
        step = int((counter[k] - counter[head]) & ENC_COUNTER_MASK)
        since_s = float(at_s[k] - times[rows[head]])
        onward = since_s >= (step - 1.5) * period_s  # as late as a step forward that long
        booted = bool(((boots > rows[head]) & (boots < rows[k])).any())
        if booted:
            head = k  # a new firmware's COUNTER
        elif since_s >= (MAX_BEHIND + 1) * period_s and onward:
            sent_s = _partner_sent_s(k, rows, counter, enc_counter, partner, boots, times)
            stepped_s = float(times[rows[head]]) + step * period_s  # sent on from the head
            if sent_s is None or abs(sent_s - stepped_s) > 0.5 * period_s:
                head = k  # one that came after a silence
            else:  # sent before the silence, with its partner, the step on from the head
                at[k], at_s[k] = _place(track, sent_s), sent_s
        elif step == 0:
            continue  # the same frame again (a duplicate)
        elif step <= HALF_LAP and (step <= MIN_BEHIND or onward):
            head = k  # sent on: a short step (after late frames), or a long one as late as it is
        elif (ENC_COUNTER_LAP - step >= MIN_BEHIND
              or since_s + (ENC_COUNTER_LAP - step) * period_s >= MIN_BEHIND * period_s):
            # behind, or a long step forward too soon; or a short way behind a head that
            # came long before it (its firmware fell silent after it: a reboot)
            sent_s = float(times[rows[head]]) - (ENC_COUNTER_LAP - step) * period_s
            at[k], at_s[k] = _place(track, sent_s), sent_s
    return at, at_s


def halves_sent_at(frames: FrameArrays, track: EncoderTrack,
                   halves: list[tuple[IntArray, IntArray, IntArray]],
                   boots: IntArray) -> list[tuple[IntArray, FloatArray]]:
    """``sent_at`` of both pose messages (each: log positions, COUNTER, ENC_COUNTER), each read
    again with the other's first reading as its ``partner``."""
    first = [sent_at(frames, track, rows, counter, boots) for rows, counter, _ in halves]
    return [sent_at(frames, track, rows, counter, boots, enc,
                    Partner(*halves[1 - i], first[1 - i][1]))
            for i, (rows, counter, enc) in enumerate(halves)]


def _place(track: EncoderTrack, sent_s: float) -> int:
    """The log position a frame sent at ``sent_s`` names its encoder frame from: after the
    latest accepted encoder frame logged by then."""
    latest = int(np.searchsorted(track.timestamp_s, sent_s, side="right")) - 1
    return int(track.index[latest]) + 1 if latest >= 0 else 0


def _partner_sent_s(k: int, rows: IntArray, counter: IntArray, enc_counter: IntArray | None,
                    partner: Partner | None, boots: IntArray,
                    times: FloatArray) -> float | None:
    """When frame ``k``'s pose was sent, by its partner: the other half of its COUNTER and
    ENC_COUNTER logged before it, sent less than a COUNTER lap (less half a period) before it
    was logged (the pair comes again a lap of sends later), no boot between; None without
    one."""
    if partner is None or enc_counter is None:
        return None
    row, logged_s = int(rows[k]), float(times[rows[k]])
    lap_s = (ENC_COUNTER_LAP - 0.5) * contract.cycle_time_s("ODOM_POSE_X")
    mine = np.flatnonzero((partner.rows < row) & (partner.counter == counter[k])
                          & (partner.enc_counter == enc_counter[k])
                          & (partner.sent_s > logged_s - lap_s))
    if len(mine) == 0:
        return None
    j = int(mine[-1])
    if ((boots > partner.rows[j]) & (boots < row)).any():
        return None
    return float(partner.sent_s[j])


def status_pages_sent_at(frames: FrameArrays, decoder: BulkDecoder,
                         positions: IntArray) -> IntArray:
    """The log position each rotating ODOM_STATUS page at ``positions`` was sent at: its
    firmware sends each cycle's summary (page 0, E2E COUNTER c - 1) and then the page (COUNTER
    c) in the same tick, so a page logged after a later summary (a delaying bus held it back)
    was sent right after the latest summary of COUNTER c - 1 logged before it, within two
    cycles; else where it was logged. ``reboots.counted_start`` counts the firmware's
    WHEEL_ENCODERS E2E counts back from the latest encoder frame before the page: from where it
    was logged, a page 120 ms late counted 12 frames late. Kobuki square 813, 9 s,
    ``delay=0.1:120``: the counts page of 0.101 s logged at 0.221 s put the power-up's prime at
    0.13 s for 0.01 s; none of the fit's candidates (``replay_lives.fit_first_prime``: 0.13 s
    and 8 frames before) was the frame the firmware primed on, none of 433 poses compared
    identical and the replay FAILed the correct firmware by 16.7 mm."""
    sent = np.asarray(positions, dtype=np.int64).copy()
    try:
        summary = decoder.decode_page(frames, "ODOM_STATUS", 0)
        rows = decoder.select(frames, "ODOM_STATUS").astype(np.int64)
        counters = decoder.decode(frames, "ODOM_STATUS")["COUNTER"].astype(np.int64)
    except (DecodeError, KeyError):
        return sent
    if "COUNTER" not in summary:
        return sent
    times = np.asarray(frames.timestamp_s, dtype=np.float64)
    window_s = 2 * contract.cycle_time_s("ODOM_STATUS")
    at = np.asarray(summary["index"], dtype=np.int64)
    counter = np.asarray(summary["COUNTER"], dtype=np.int64)
    for k, position in enumerate(sent.tolist()):
        mine = np.flatnonzero(rows == position)
        if len(mine) == 0:
            continue
        wanted = int((counters[mine[0]] - 1) & ENC_COUNTER_MASK)
        before = at[(at < position) & (counter == wanted)
                    & (times[at] > times[position] - window_s)]
        sent[k] = int(before[-1]) + 1 if len(before) else position
    return sent
