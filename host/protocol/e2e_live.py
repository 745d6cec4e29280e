"""AUTOSAR E2E Profile 2 checked one frame at a time, for live monitoring (``odocan monitor``,
the MQTT bridge, the fleet): the same rules as ``host.protocol.e2e.check_frames`` on a whole
log (``SequenceState``), with the receive periods counted from each frame's bus time and a
stalled recorder's release read wide (``host.protocol.e2e_evidence.ReleaseWatch``). Moved out of
``host.protocol.e2e`` at its 500 lines."""

from __future__ import annotations

import math
from collections.abc import Callable
from math import isfinite
from typing import TYPE_CHECKING

from odocan.host.protocol import busfacts
from odocan.host.protocol.decode import frame_key
from odocan.host.protocol.e2e import (
    COUNTER_MASK,
    CRC_ERROR,
    OK,
    UNKNOWN,
    UNKNOWN_ID,
    UNKNOWN_KEYS,
    UNPROTECTED,
    WRONG_DLC,
    E2EMessage,
    SequenceState,
    e2e_messages,
)
from odocan.host.protocol.e2e_crc import (
    PLACE_B2,
    PLACE_B3,
    PLACE_B4,
    PLACE_B5,
    PLACE_B6,
    PLACE_B7,
    byte1_table,
    crc8h2f_p02_one,
)
from odocan.host.protocol.e2e_cycles import new_cycle_s
from odocan.host.protocol.e2e_evidence import CAPTURE_HOLD_CYCLES, ReleaseWatch
from odocan.host.protocol.e2e_halts import SENDS, HaltWatch
from odocan.host.protocol.e2e_held import HELD, forced, new_cycle_pending, readings_differ
from odocan.host.protocol.e2e_periods import (
    CAPTURE_TOLERANCE_CYCLES,
    receive_period_count,
)
from odocan.host.protocol.e2e_silence import SILENCE_PERIODS
from odocan.sim import contract

if TYPE_CHECKING:  # a cantools Database or a plan of it
    from odocan.host.protocol.dbcplan import DatabaseSpec


class _Live:
    """A protected message heard (``E2EMonitor.check``): its fields, state, last frame's time s,
    its CRC table (``e2e_crc.byte1_table``) and the gaps within which a frame adds one receive
    period whatever the rest of the rule (``one_period_s``)."""

    __slots__ = ("byte1", "cycle_s", "data_ids", "last", "last_s", "length", "min_periods",
                 "one_from_s", "one_to_s", "silence_s", "state")

    def __init__(self, config: E2EMessage, state: SequenceState, data_ids: tuple[int, ...],
                 last_s: float | None, last: int) -> None:
        self.length, self.data_ids, self.state = config.length, data_ids, state
        self.cycle_s, self.min_periods, self.last_s = config.cycle_s, config.min_periods, last_s
        self.last = last  # the last frame's COUNTER, -1 when its CRC was wrong
        self.byte1 = byte1_table(data_ids)
        self.one_from_s, self.one_to_s = one_period_s(config.cycle_s, config.min_periods)
        # an accepted frame this long (s) or more after the last is a silence (``is_silence``'s
        # product, the same float); no receive period: never
        self.silence_s = (math.inf if state.period_s is None
                          else SILENCE_PERIODS * state.period_s)


def one_period_s(cycle_s: float | None, min_periods: int) -> tuple[float, float]:
    """Gaps (s, from, to) within which a frame of a message adds one receive period to its
    window, whatever ``E2EMonitor._periods`` would find (the usual frame, on time: the rules
    not run). For a message with ``min_periods`` 1, ``period_count``'s ``max(1, round(dt /
    cycle))`` is 1 below 1.5 periods: a gap of at most 1.4 cycles. For one checked per period
    (``min_periods`` 0) a gap of 0.6 to 1.04 cycles (``x`` within 0.5 to 1.05, float error
    included) gives 1 by ``period_count`` (a wrong CRC) and by ``receive_period_count`` when
    the COUNTER steps by one (its ``s`` 1 and ``|e|`` at most 0.5, brought below the lag of 0.1
    by any tolerance of 0.45 or more: 1): ``check`` asks that step too. Without a cycle (or
    another minimum): none, an empty range. tests/test_e2e_live_shortcuts.py holds the edges."""
    if cycle_s is None:
        return math.inf, -math.inf
    if min_periods == 1:
        return -math.inf, 1.4 * cycle_s
    if min_periods == 0:
        return 0.6 * cycle_s, 1.04 * cycle_s
    return math.inf, -math.inf


class _SeenOnce:
    """A ``ReleaseWatch`` that notes no frame: a held frame given back was noted when heard."""

    def __init__(self, watch: ReleaseWatch | _SeenOnce) -> None:
        self.released: Callable[[float | None], bool] = watch.released
        self.silent_after: Callable[[float | None], bool] = watch.silent_after

    def seen(self, timestamp_s: float, key: int = -1) -> None:
        """Noted already (``E2EMonitor.check_as``)."""


class E2EMonitor:
    """The same rules, one frame at a time, for live monitoring.

    ``check`` returns one of ``"ok"``, ``"oksomelost"``, ``"repeated"``, ``"wrong_sequence"``,
    ``"crc_error"`` (E2E statuses), ``"unprotected"`` (a message without E2EDataIDs, taken as it
    is), ``"unknown_id"`` or ``"wrong_dlc"`` (not checked). Give ``timestamp_s`` (seconds, e.g.
    ``msg.timestamp``) to widen the window with time as ``check_frames`` does; without it each
    frame counts as one period.
    """

    def __init__(self, db: DatabaseSpec | None = None) -> None:
        self._configs = e2e_messages(db if db is not None else contract.database())
        self._states: dict[int, SequenceState] = {}
        self._live: dict[int, _Live] = {}  # protected messages heard: what ``check`` needs
        self._unknown = dict.fromkeys(UNKNOWN_KEYS, 0)
        self.holds: bool = False  # "held" for a frame the stamps cannot decide (docstring)
        self.retakes = 0  # ``retake``s made (a hold's verdicts after one are stale: livesettle)
        self.retaken: tuple[int, int, float] | None = None  # the latest: CAN id, COUNTER, s
        self._held_s: float | None = None  # the bus time of the frame held last
        cycle_s = min((c.cycle_s for c in self._configs.values()
                       if c.min_periods == 0 and c.cycle_s), default=0.01)
        self._releases: ReleaseWatch | _SeenOnce = ReleaseWatch(cycle_s)  # (check_as: _SeenOnce)
        self._halts = HaltWatch(
            frozenset(k for k, c in self._configs.items() if c.name in SENDS),
            next((k for k, c in self._configs.items() if c.name == busfacts.ENC_MESSAGE), -1))

    def check(
        self, can_id: int, data: bytes, extended: bool = False, timestamp_s: float | None = None
    ) -> str:
        """Judge one data frame (identifier, payload); count and return its status (a message
        heard before, with its DLC, by its ``_Live``: one lookup a frame of a fleet's robots).
        ``extended`` and ``timestamp_s`` may be given by position (the bridge's per-ID plans,
        ``host.mqtt.liveplan``: a call with keywords takes CPython's slower call path)."""
        if timestamp_s is not None:
            self._releases.seen(timestamp_s, can_id)
            self._halts.seen(can_id, timestamp_s, data[1] & COUNTER_MASK if len(data) > 1 else 0)
        live = self._live.get(frame_key(can_id, True) if extended else can_id)
        if live is None or len(data) != live.length:
            return self._check_first(frame_key(can_id, extended), data, timestamp_s)
        counter = data[1]  # 8 bytes (Profile 2): the CRC by place (``byte1_table``)
        crc_ok = (live.byte1[counter] ^ PLACE_B2[data[2]] ^ PLACE_B3[data[3]] ^ PLACE_B4[data[4]]
                  ^ PLACE_B5[data[5]] ^ PLACE_B6[data[6]] ^ PLACE_B7[data[7]]) == data[0]
        counter &= COUNTER_MASK
        periods = 1  # (the first frame, or no cycle: ``period_count``'s 1)
        if timestamp_s is not None:
            last, live.last_s = live.last_s, timestamp_s
            if last is not None and not (  # (else on time: one period, ``one_period_s``)
                    live.one_from_s <= timestamp_s - last <= live.one_to_s
                    and (live.min_periods or (counter - live.last) & COUNTER_MASK == 1)):
                periods = self._periods(live, timestamp_s - last, last, crc_ok, counter)
                if (self.holds and crc_ok and live.last >= 0 and live.min_periods == 0
                        and (readings_differ(live.state, timestamp_s - last,
                                             (counter - live.last) & COUNTER_MASK, counter,
                                             live.cycle_s)
                             or new_cycle_pending(live.state, counter, timestamp_s)
                             or (self._halts.after(timestamp_s) and not live.state.waiting
                                 and (counter - live.state.last_valid) & COUNTER_MASK > 1))):
                    live.last_s = last  # not heard yet: given back by ``check_as``
                    self._held_s = timestamp_s  # (its ``ReleaseWatch.seen`` was: once)
                    return HELD
        live.last = counter if crc_ok else -1
        state = live.state
        if (crc_ok and not state.waiting and (counter - state.last_valid) & COUNTER_MASK == 1
                and timestamp_s is not None and state.last_ok_s is not None
                and timestamp_s - state.last_ok_s < live.silence_s):
            # ``SequenceState.check``'s usual frame in line (per frame of every robot): OK, the
            # window restarted, no silence before it (tests/test_e2e_live_fast.py)
            state.last_valid, state.window = counter, state.max_delta_init
            state.last_valid_s = state.last_ok_s = timestamp_s
            state.counts["ok"] += 1
            return OK
        return state.check(crc_ok, counter, periods, timestamp_s)

    def _periods(self, live: _Live, dt_s: float, last_s: float, crc_ok: bool,
                 counter: int) -> int:
        """The receive periods a frame ``dt_s`` after the message's last (heard at ``last_s``)
        adds to its window, as ``check_frames`` counts them."""
        cycle_s = live.cycle_s
        if cycle_s is None:
            return 1
        if crc_ok and live.last >= 0 and live.min_periods == 0:  # as ``frame_periods``
            return receive_period_count(  # the wide reading after a release
                dt_s, (counter - live.last) & COUNTER_MASK, cycle_s,
                CAPTURE_HOLD_CYCLES if self._releases.released(last_s)
                or self._releases.silent_after(last_s) else CAPTURE_TOLERANCE_CYCLES)
        if isfinite(dt_s):  # ``period_count`` in line (per frame)
            return max(live.min_periods, round(dt_s / cycle_s))
        return 1

    def check_as(self, can_id: int, data: bytes, timestamp_s: float, accepted: bool) -> str:
        """``check`` of a frame held (``holds``), given back with the verdict of the whole log's
        rule over the frames held (``accepted``: ``host.judge.livesettle``): the state and the
        counts as that verdict leaves them (``e2e_held.forced``)."""
        live = self._live.get(can_id)
        state = None if live is None else live.state
        before = None if state is None else (dict(state.counts), state.window, state.last_valid,
                                             state.waiting, state.last_ok_s)
        periods = (1 if live is None or len(data) != live.length  # (a wrong DLC: check's)
                   else self._periods_held(live, data, timestamp_s))
        was, releases = self.holds, self._releases
        self.holds = False
        if timestamp_s == self._held_s:  # the frame that was held: heard once already
            self._held_s, self._releases = None, _SeenOnce(releases)
        try:
            status = self.check(can_id, data, False, timestamp_s)
        finally:
            self.holds, self._releases = was, releases
        if state is None or before is None or status in (CRC_ERROR, UNKNOWN_ID, WRONG_DLC):
            return status
        return forced(state, before, (status, periods), data[1] & COUNTER_MASK, timestamp_s,
                      accepted)

    def _periods_held(self, live: _Live, data: bytes, timestamp_s: float) -> int:
        """The receive periods ``check`` finds for a frame held (``check_as``; as ``check``)."""
        counter, last = data[1] & COUNTER_MASK, live.last_s
        if last is None or (live.one_from_s <= timestamp_s - last <= live.one_to_s
                            and (live.min_periods or (counter - live.last) & COUNTER_MASK == 1)):
            return 1
        crc_ok = crc8h2f_p02_one(data, live.data_ids[counter]) == data[0]
        return self._periods(live, timestamp_s - last, last, crc_ok, counter)

    def after_halt(self, timestamp_s: float) -> bool:
        """Whether bus time ``timestamp_s`` lies within a lock-out after the firmware resumed
        from an MCU halt (``e2e_halts.HaltWatch.after``; the frames checked with a time)."""
        return self._halts.after(timestamp_s)

    def last_taken(self, can_id: int) -> tuple[int, float] | None:
        """COUNTER and bus time (s) of the message's last frame accepted, if known."""
        state = self._states.get(can_id)
        if state is None or state.waiting or state.last_ok_s is None:
            return None
        return state.last_valid, state.last_ok_s

    def _check_first(self, key: int, data: bytes, timestamp_s: float | None) -> str:
        """``check`` of a message not heard yet (makes its ``_Live``), unknown, or off its DLC."""
        config = self._configs.get(key)
        if config is None:
            self._unknown["unknown_id"] += 1
            return UNKNOWN_ID
        if len(data) != config.length:
            self._unknown["wrong_dlc"] += 1
            return WRONG_DLC
        if config.data_ids is None:
            self._unknown["unprotected"] += 1
            return UNPROTECTED
        state = self._states.get(key)
        if state is None:
            state = self._states[key] = SequenceState(config.max_delta_init,
                                                      cycle_s=new_cycle_s(config),
                                                      period_s=config.cycle_s)
        counter = data[1] & COUNTER_MASK
        crc_ok = crc8h2f_p02_one(data, config.data_ids[counter]) == data[0]
        self._live[key] = _Live(config, state, config.data_ids, timestamp_s,  # one period
                                counter if crc_ok else -1)
        return state.check(crc_ok, counter, 1, timestamp_s)

    def restart_sequence(self, can_id: int, *, extended: bool = False) -> None:
        """The sender of this message restarted (a reboot: its COUNTER starts again): its next
        frame starts the sequence afresh, as the first frame heard does. The counts stay."""
        state = self._states.get(frame_key(can_id, extended))
        if state is not None:
            state.waiting = True

    def retake(self, can_id: int, counter: int, timestamp_s: float) -> None:
        """A frame of the message refused, taken after all (a receiver that booted at it took
        it: ``host.judge.liveboottick``): the sequence restarts at it, as the first frame of a
        fresh one starts it (COUNTER ``counter`` at bus time ``timestamp_s``). The counts
        stay."""
        state, live = self._states.get(can_id), self._live.get(can_id)
        if state is None or live is None:
            return
        state.waiting, state.last_valid, state.window = False, counter, state.max_delta_init
        state.last_valid_s = state.last_ok_s = timestamp_s
        live.last = counter
        self.retakes += 1
        self.retaken = (can_id, counter, timestamp_s)

    def count_frame_kind(self, *, error: bool = False, remote: bool = False) -> None:
        """Count an error or remote frame (they are never checked)."""
        if error:
            self._unknown["error_frames"] += 1
        elif remote:
            self._unknown["remote_frames"] += 1

    def counts(self) -> dict[str, dict[str, int]]:
        """Counts per message name seen so far (``E2E_KEYS``) and the ``"unknown"`` section."""
        result = {self._configs[key].name: dict(s.counts) for key, s in self._states.items()}
        result[UNKNOWN] = dict(self._unknown)
        return result
