"""A firmware reboot told by NAV_STATUS's E2E COUNTER restarting (issue #11): a second message's
sequence broken beside the boot summary's, where the twists' DISTANCE cannot show it.

A reset 32 k ticks into the firmware's first second whose power-up pose pair the bus lost breaks
only ODOM_STATUS's sequence among the pose's and summary's COUNTERs (``bootticks``,
``distfall``); the DISTANCE fall that told it is lost with the new firmware's first twists: from
10 of them lost on (200 ms) the new life has driven past the old life's DISTANCE before a twist
is heard, no fall shows, and every judge FAILed the correct firmware by 93 mm (tick 32) or
0.25 m (tick 64) against the old life's reference.

What else a reset leaves on the bus: every COUNTER the firmware sends starts at 0 (E2E Profile
2), NAV_STATUS's too, sent in the power-up tick after the summary (firmware/reports.py; the
DBC: "every 100 ms, and at once in the 10 ms tick where STATE or GOAL_ID changes"), so at most
one a firmware tick (``TICK_S``, the encoder period the firmware steps on). One life gets from
COUNTER c to c' in ``(c' - c - 1) mod 16 + 1`` frames, one tick apart at the least (lost frames,
stalls: later), so a NAV_STATUS heard sooner than that after the one before broke the sequence:
a new firmware sent it (``restarts``). In the first second the old life's NAV_STATUS COUNTER is
at most 10, its new one's 0 comes within a tick of the old one's frames: 6 frames needed at
least, 60 ms, where one tick passed. The same COUNTER again is left out (a recorder's repeat of
a frame would read as a restart), and so is any COUNTER above ``RESTART_COUNTERS`` (the new
firmware's first three, the two summaries after the boot summary).

Read as the DISTANCE falls are (``distfall.Falls``: bus time, COUNTER, the frame before's bus
time) and tied to a boot summary by the same rules (``bootticks.tied_to_boot``,
``tied_to_run``, ``latefall.tied_late``: their COUNTER bound is the pose period's, twice this
tick, so stricter than NAV_STATUS needs): the summary breaking ODOM_STATUS's sequence, the first
pose after it restarting a small COUNTER soon, and the next summary continuing it, with this
second message's restart, tell the reboot (``bootticks.boot_ahead``'s ``fell``). A firmware
that sends no NAV_STATUS, or a log that lost its first ones too, leaves the reboot to the
DISTANCE fall as before.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.distfall import Falls, fall_times, joined, no_falls
from odocan.host.judge.heldfall import Heard, unheld_falls
from odocan.host.protocol import busfacts
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e import crc8h2f_p02, crc8h2f_p02_one, e2e_messages

NAV_MESSAGE = "NAV_STATUS"
NAV_BYTES = 8  # its length (the DBC): what its E2E CRC covers
TICK_S = busfacts.ENC_CYCLE_S  # the firmware's tick: at most one NAV_STATUS in it (the DBC)
COUNTER_LAP = busfacts.ENC_COUNTER_LAP  # every E2E COUNTER's lap: 16
SLACK_S = busfacts.POSE_CYCLE_MS / 4000  # a recorder's stamping (``bootticks``' slack)
RESTART_COUNTERS = 3  # a new firmware's first NAV_STATUS COUNTERs read as a restart
# the twist's, NAV_STATUS's, and the last twists heard (``heldfall``)
Carried = tuple[tuple[float, int] | None, tuple[float, int] | None, Heard]


def restarts(before_counter: int, before_s: float, counter: int, t_s: float) -> bool:
    """Whether a NAV_STATUS of E2E ``counter`` heard at ``t_s`` after one of ``before_counter``
    heard at ``before_s`` broke the sequence (module docstring): a COUNTER of the new
    firmware's first ``RESTART_COUNTERS``, not the same again, sooner than one life sends the
    frames between at one a tick."""
    frames = (counter - before_counter - 1) % COUNTER_LAP + 1
    return bool(counter != before_counter and counter < RESTART_COUNTERS
                and 0.0 <= t_s - before_s < frames * TICK_S - SLACK_S)


def _nav_ids(decoder: BulkDecoder) -> tuple[int, ...] | None:
    """NAV_STATUS's E2E DataIDs in the decoder's DBC (None: unprotected)."""
    config = e2e_messages(decoder.db).get(decoder.message(NAV_MESSAGE).frame_id)
    return None if config is None else config.data_ids


def restart_times(frames: FrameArrays, decoder: BulkDecoder,
                  carried: tuple[float, int] | None = None
                  ) -> tuple[Falls, tuple[float, int] | None]:
    """The NAV_STATUS frames of ``frames`` (their CRC holding) that ``restarts`` the sequence
    of the one before, as ``Falls``, and the latest one's (bus time, COUNTER) for the next
    chunk (``carried``: the one before ``frames``)."""
    try:
        rows = np.asarray(decoder.select(frames, NAV_MESSAGE), dtype=np.int64)
        ids = _nav_ids(decoder)
    except (DecodeError, KeyError):
        return no_falls(), carried
    data = frames.data[rows]
    counter = (data[:, 1] & ENC_COUNTER_MASK).astype(np.int64)
    good = np.ones(len(rows), dtype=bool)
    if ids:
        good = crc8h2f_p02(data, np.array(ids, dtype=np.uint8)[counter]) == data[:, 0]
    t_s = frames.timestamp_s[rows].astype(np.float64)[good]
    counter = counter[good]
    if carried is not None:
        t_s = np.concatenate(([carried[0]], t_s))
        counter = np.concatenate(([carried[1]], counter))
    if len(t_s) == 0:
        return no_falls(), carried
    frames_between = (counter[1:] - counter[:-1] - 1) % COUNTER_LAP + 1
    gap = t_s[1:] - t_s[:-1]
    broke = ((counter[1:] != counter[:-1]) & (counter[1:] < RESTART_COUNTERS) & (gap >= 0.0)
             & (gap < frames_between * TICK_S - SLACK_S))
    return (Falls(t_s[1:][broke], counter[1:][broke], t_s[:-1][broke]),
            (float(t_s[-1]), int(counter[-1])))


def merged(first: Falls, then: Falls) -> Falls:
    """Two sets of falls (in bus-time order each) as one in bus-time order."""
    both = joined(first, then)
    order = np.argsort(both.times_s, kind="stable")
    return Falls(both.times_s[order], both.counters[order], both.befores_s[order])


def second_evidence(frames: FrameArrays, decoder: BulkDecoder, small: int,
                    carried: Carried | None = None) -> tuple[Falls, Carried]:
    """The twists whose DISTANCE fell (``distfall.fall_times``) and the NAV_STATUS frames that
    restarted the sequence (``restart_times``) of ``frames``, in bus-time order, and what the
    next chunk carries (``carried``: this chunk's). A twist held back is no fall
    (``heldfall``)."""
    twist, nav, heard = (None, None, ()) if carried is None else carried
    falls, twist_after = fall_times(frames, decoder, small, twist)
    falls, heard_after = unheld_falls(frames, decoder, falls, heard)
    navs, nav_after = restart_times(frames, decoder, nav)
    return merged(falls, navs), (twist_after, nav_after, heard_after)


def restarted_within(data_ids: tuple[int, ...] | None, heard: Iterable[tuple[float, bytes]],
                     tied: Callable[[float, int, float], bool]) -> bool:
    """Whether a NAV_STATUS of ``heard`` (bus time, bytes; in order; its CRC holding with
    ``data_ids``, None: unprotected) ``restarts`` the sequence of the one heard before it where
    ``tied`` takes it (its bus time, COUNTER and the bus time of the frame before it): the live
    judges' ``restart_times``, read only when a summary needs it."""
    before: tuple[float, int] | None = None
    for t_s, data in heard:
        if len(data) != NAV_BYTES:  # a babbler's short frame on the ID: no CRC, no COUNTER
            continue
        counter = data[1] & ENC_COUNTER_MASK
        if data_ids and data[0] != crc8h2f_p02_one(data, data_ids[counter]):
            continue
        if (before is not None and restarts(before[1], before[0], counter, t_s)
                and tied(t_s, counter, before[0])):
            return True
        before = (t_s, counter)
    return False
