"""AUTOSAR E2E Profile 2 checked one frame at a time, for live monitoring (``odocan monitor``,
the MQTT bridge, the fleet): the same rules as ``host.protocol.e2e.check_frames`` on a whole
log (``SequenceState``), with the receive periods counted from each frame's bus time and a
stalled recorder's release read wide (``host.protocol.e2e_evidence.ReleaseWatch``). Moved out of
``host.protocol.e2e`` at its 500 lines."""

from __future__ import annotations

from math import isfinite
from typing import TYPE_CHECKING

from odocan.host.protocol.decode import frame_key
from odocan.host.protocol.e2e import (
    COUNTER_MASK,
    UNKNOWN,
    UNKNOWN_ID,
    UNKNOWN_KEYS,
    UNPROTECTED,
    WRONG_DLC,
    E2EMessage,
    SequenceState,
    e2e_messages,
)
from odocan.host.protocol.e2e_crc import crc8h2f_p02_one
from odocan.host.protocol.e2e_cycles import new_cycle_s
from odocan.host.protocol.e2e_evidence import CAPTURE_HOLD_CYCLES, ReleaseWatch
from odocan.host.protocol.e2e_periods import (
    CAPTURE_TOLERANCE_CYCLES,
    receive_period_count,
)
from odocan.sim import contract

if TYPE_CHECKING:  # a cantools Database or a plan of it
    from odocan.host.protocol.dbcplan import DatabaseSpec


class _Live:
    """A protected message heard (``E2EMonitor.check``): its fields, state, last frame's time s."""

    __slots__ = ("cycle_s", "data_ids", "last", "last_s", "length", "min_periods", "state")

    def __init__(self, config: E2EMessage, state: SequenceState, data_ids: tuple[int, ...],
                 last_s: float | None, last: int) -> None:
        self.length, self.data_ids, self.state = config.length, data_ids, state
        self.cycle_s, self.min_periods, self.last_s = config.cycle_s, config.min_periods, last_s
        self.last = last  # the last frame's COUNTER, -1 when its CRC was wrong


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
        self._releases = ReleaseWatch(min((c.cycle_s for c in self._configs.values()
                                           if c.min_periods == 0 and c.cycle_s), default=0.01))

    def check(
        self, can_id: int, data: bytes, *, extended: bool = False, timestamp_s: float | None = None
    ) -> str:
        """Judge one data frame (identifier, payload); count and return its status (a message
        heard before, with its DLC, by its ``_Live``: one lookup a frame of a fleet's robots)."""
        if timestamp_s is not None:
            self._releases.seen(timestamp_s, can_id)
        live = self._live.get(frame_key(can_id, True) if extended else can_id)
        if live is None or len(data) != live.length:
            return self._check_first(frame_key(can_id, extended), data, timestamp_s)
        counter = data[1] & COUNTER_MASK
        crc_ok = crc8h2f_p02_one(data, live.data_ids[counter]) == data[0]
        periods = 1  # (the first frame, or no cycle: ``period_count``'s 1)
        if timestamp_s is not None:
            last, live.last_s = live.last_s, timestamp_s
            cycle_s = live.cycle_s
            if last is None or cycle_s is None:
                pass
            elif crc_ok and live.last >= 0 and live.min_periods == 0:  # as ``frame_periods``
                periods = receive_period_count(  # the wide reading after a release
                    timestamp_s - last, (counter - live.last) & COUNTER_MASK, cycle_s,
                    CAPTURE_HOLD_CYCLES if self._releases.released(last)
                    or self._releases.silent_after(last)
                    else CAPTURE_TOLERANCE_CYCLES)
            elif isfinite(dt_s := timestamp_s - last):  # ``period_count`` in line (per frame)
                periods = max(live.min_periods, round(dt_s / cycle_s))
        live.last = counter if crc_ok else -1
        return live.state.check(crc_ok, counter, periods, timestamp_s)

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
