"""The host's AUTOSAR E2E Profile 2 receiver: vectorised over a log, or streaming for a live bus.

The host's own implementation of what the firmware does in ``firmware.e2e`` (dbc/README.md):

* **CRC8H2F** (polynomial 0x2F, initial value 0xFF, final XOR 0xFF) over bytes 1..7 and then the
  data ID ``E2EDataIDs[COUNTER]``, the 16-entry list of the DBC message attribute ``E2EDataIDs``.
  Over a whole log: one table lookup per byte column for all frames at once (``e2e_crc``).
* **Sequence** (``E2E_P02Check``), per message in bus order, on the frames whose CRC is right:
  ``delta = (COUNTER - last_valid) mod 16``: 1 OK; 0 REPEATED (dropped); 2..MaxDeltaCounter
  OKSOMELOST (used, ``delta - 1`` frames lost); beyond WRONGSEQUENCE (dropped, the reference counter
  kept: R4.0 has no re-sync counter, the widening window lets the sender back in). The first frame
  is OK.
* **MaxDeltaCounter**: as in the firmware, it restarts from ``MaxDeltaCounterInit`` at each accepted
  frame and grows by one per receive period (up to 15) before a frame is judged. The firmware
  counts its periods with ``check(None)`` calls; the host counts them from the timestamps:
  a frame ``dt`` after the message's previous frame adds ``max(1, round(dt / period))`` periods,
  the period ``GenMsgCycleTime`` over ``E2EFramesPerCycle`` (ODOM_STATUS's summary and page, the
  three parts of SIM_TRUTH: a COUNTER step a frame, as AUTOSAR's receiver checks once per frame
  it expects; one a cycle let a burst leave every later page WRONG_SEQUENCE till the window hit
  15). MaxDeltaCounterInit is 1 for ``Cyclic`` messages and 15 for the others
  (event messages, ``CyclicIfActive`` MOTOR_CMD), as the firmware and the motor controller use,
  except WHEEL_ENCODERS (``PER_PERIOD_WINDOW``): the firmware checks them with init 0 and a
  window widened once per tick (``window_per_period``), so a frame there adds
  ``round(dt / cycle)`` periods, none within half a period: a babbler's or a forger's frame
  sent with a genuine one cannot open the window to itself.
  A frame of those messages late on the bus (a ``delay`` fault, a frame reordered) is not
  rounded: between two frames whose CRCs are right, the periods are the sender's COUNTER step
  plus the ticks the late one waited (``receive_periods``), so a frame late by exactly half a
  period is no tie (round-half-even flipped on 1 ns of timestamp).
  *Intended difference*: two frames of one of those messages within one period add two periods
  in the firmware (two checks) and in the host (two frames), but a frame with the wrong DLC,
  which the firmware drops before the check (no ``check(None)`` for that tick either), leaves
  no trace here but the time that passed.

``ok`` counts the frames accepted (OK or OKSOMELOST), as the firmware's ``*_E2E_OK`` signals;
``lost`` the frames skipped by OKSOMELOST; ``crc_errors`` bad CRCs. Frames of IDs the DBC does not
know, of the wrong DLC, error and remote frames are counted in the ``"unknown"`` section, never
fatal; messages without ``E2EDataIDs`` are taken unchecked and counted there as ``unprotected``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FLAG_ERROR, FLAG_REMOTE, FrameArrays
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.protocol.decode import frame_groups, frame_keys
from odocan.host.protocol.e2e_bound import beyond_bound
from odocan.host.protocol.e2e_config import (  # re-exported (their old home)
    COUNTER_LAP as COUNTER_LAP,
)
from odocan.host.protocol.e2e_config import (
    MAX_DELTA_COUNTER as MAX_DELTA_COUNTER,
)
from odocan.host.protocol.e2e_config import (
    PER_PERIOD_WINDOW as PER_PERIOD_WINDOW,
)
from odocan.host.protocol.e2e_config import E2EConfigError as E2EConfigError
from odocan.host.protocol.e2e_config import E2EMessage as E2EMessage
from odocan.host.protocol.e2e_config import e2e_messages as e2e_messages
from odocan.host.protocol.e2e_crc import (  # re-exported (their old home)
    CRC8H2F_INIT as CRC8H2F_INIT,
)
from odocan.host.protocol.e2e_crc import (
    CRC8H2F_POLY as CRC8H2F_POLY,
)
from odocan.host.protocol.e2e_crc import (
    CRC8H2F_TABLE as CRC8H2F_TABLE,
)
from odocan.host.protocol.e2e_crc import (
    CRC8H2F_XOR_OUT as CRC8H2F_XOR_OUT,
)
from odocan.host.protocol.e2e_crc import (
    P02_LENGTH as P02_LENGTH,
)
from odocan.host.protocol.e2e_crc import (
    crc8h2f_p02 as crc8h2f_p02,
)
from odocan.host.protocol.e2e_crc import (
    crc8h2f_p02_one as crc8h2f_p02_one,
)
from odocan.host.protocol.e2e_cycles import (
    COUNTER_CYCLE,
    new_cycle_frames,
    new_cycle_s,
    new_cycles,
)
from odocan.host.protocol.e2e_decided import all_decided, by_readings, reading_key
from odocan.host.protocol.e2e_evidence import (
    Evidence,
    evidence_frames,
    pose_evidence,
    readings,
    recorder_releases,
    settle,
)
from odocan.host.protocol.e2e_pages import OkPages, by_pages, ok_pages
from odocan.host.protocol.e2e_periods import (
    frame_periods,
)
from odocan.host.protocol.e2e_periods import (
    period_count as period_count,  # re-exported (their old home)
)
from odocan.host.protocol.e2e_periods import (
    periods_between as periods_between,
)
from odocan.host.protocol.e2e_repeats import repeats_by_pages
from odocan.host.protocol.e2e_silence import add_silence, is_silence, silences
from odocan.host.protocol.e2e_skipveto import by_page_skips

if TYPE_CHECKING:  # a cantools Database or a plan of it (host.protocol.dbcplan)
    from odocan.host.protocol.dbcplan import DatabaseSpec

E2E_KEYS = ("ok", "lost", "repeated", "crc_errors", "wrong_sequence")
UNKNOWN = "unknown"  # the section of check_frames' counts for frames that are not checked
UNKNOWN_KEYS = ("unknown_id", "wrong_dlc", "error_frames", "remote_frames", "unprotected")

OK, OKSOMELOST, REPEATED, WRONG_SEQUENCE, CRC_ERROR = (
    "ok", "oksomelost", "repeated", "wrong_sequence", "crc_error"
)
UNKNOWN_ID, WRONG_DLC, UNPROTECTED = "unknown_id", "wrong_dlc", "unprotected"
_STATUS = (OK, OKSOMELOST, REPEATED, WRONG_SEQUENCE, CRC_ERROR)
_S_OK, _S_LOST, _S_REPEATED, _S_WRONG, _S_CRC = range(5)

COUNTER_MASK = ENC_COUNTER_MASK  # 0x0F


# --- one message's sequence (AUTOSAR E2E_P02Check), shared by both APIs ---------------------------


@dataclass(slots=True)
class SequenceState:
    """The Profile 2 check state of one message: last valid counter and the delta window.

    ``cycle_s`` (set for the messages checked per period, ``PER_PERIOD_WINDOW``; frames judged
    with their bus time ``timestamp_s``): a frame of the last valid COUNTER half a COUNTER
    cycle or more (the bus time, as ``samples.sender_seq`` counts it) after the last valid
    frame, with no frame of a right CRC between in the log, is no repeat but the sender's frame
    16 * k periods on (``host.protocol.e2e_cycles``): OKSOMELOST, 16 * k - 1 lost. A firmware
    that had the frames between (a recorder's kernel buffer dropped them) took it; refused as
    REPEATED, it left the reference and the pairing a frame short (``tests/test_recorder_gap16``).
    Frames between (refused: a lock-out after a late frame, ``gapfill``) are the firmware's too,
    so it refused this one: so does the host. The window is kept: had the firmware lost the
    frames too, it refused this one and the frames after are judged as it judges them."""

    max_delta_init: int
    waiting: bool = True  # no valid frame yet
    last_valid: int = 0
    window: int = 0  # MaxDeltaCounter
    counts: dict[str, int] = field(default_factory=lambda: dict.fromkeys(E2E_KEYS, 0))
    cycle_s: float | None = None  # the receive period when a same COUNTER may be a new cycle
    last_valid_s: float | None = None  # the last valid frame's bus time (s), when given
    period_s: float | None = None  # the receive period, for the silences (``e2e_silence``)
    last_ok_s: float | None = None  # the last accepted frame's bus time (s), when given

    def check(self, crc_ok: bool, counter: int, periods: int = 1,
              timestamp_s: float | None = None) -> str:
        """Judge one frame ``periods`` receive periods after the previous one, at bus time
        ``timestamp_s`` (s, optional); count it."""
        delta = (counter - self.last_valid) & COUNTER_MASK
        if crc_ok and (self.waiting or delta == 1):  # the usual frame: the window restarts
            status = OK
        else:
            window = self.window + periods  # at most MAX_DELTA_COUNTER (no min(): per frame)
            self.window = window if window < MAX_DELTA_COUNTER else MAX_DELTA_COUNTER
            if not crc_ok:
                self.counts["crc_errors"] += 1
                return CRC_ERROR
            if delta == 0 and (cycles := self._new_cycles(timestamp_s)):
                self.counts["lost"] += COUNTER_CYCLE * cycles - 1
                self.counts["ok"] += 1
                self.last_valid_s = timestamp_s
                self._heard(timestamp_s)
                return OKSOMELOST  # the window kept (the docstring)
            if delta == 0 or delta > self.window:
                self.last_valid_s = None  # a frame between: no new cycle till the next accepted
                self.counts["repeated" if delta == 0 else "wrong_sequence"] += 1
                return REPEATED if delta == 0 else WRONG_SEQUENCE
            status = OKSOMELOST
            self.counts["lost"] += delta - 1
        self.waiting = False
        self.last_valid = counter
        self.window = self.max_delta_init
        self.last_valid_s = timestamp_s
        self.counts["ok"] += 1
        if timestamp_s is not None:  # ``_heard`` in line (per frame of every robot)
            last_ok_s, self.last_ok_s = self.last_ok_s, timestamp_s
            if last_ok_s is not None and is_silence(timestamp_s - last_ok_s, self.period_s):
                add_silence(self.counts, timestamp_s - last_ok_s)
        return status

    def _heard(self, timestamp_s: float | None) -> None:
        """An accepted frame at ``timestamp_s``: count the silence before it, if one."""
        if timestamp_s is None:
            return
        if self.last_ok_s is not None and is_silence(timestamp_s - self.last_ok_s,
                                                     self.period_s):
            add_silence(self.counts, timestamp_s - self.last_ok_s)
        self.last_ok_s = timestamp_s

    def _new_cycles(self, timestamp_s: float | None) -> int:
        """Whole COUNTER cycles since the last valid frame (``e2e_cycles``; 0: not known)."""
        last, cycle_s = self.last_valid_s, self.cycle_s
        if cycle_s is None or timestamp_s is None or last is None:
            return 0
        return new_cycles(timestamp_s - last, cycle_s)


def sequence_statuses(
    crc_ok: npt.NDArray[np.bool_],
    counter: npt.NDArray[np.int64],
    periods: npt.NDArray[np.int64],
    max_delta_init: int,
    timestamp_s: npt.NDArray[np.float64] | None = None,
    cycle_s: float | None = None,
) -> npt.NDArray[np.int8]:
    """Status codes (``_STATUS`` order) of one message's frames in bus order.

    Vectorised on the assumption that each valid frame's predecessor was accepted; the frames
    from each place where that fails up to the next accepted frame are re-judged one by one with
    ``SequenceState`` (the cost grows with the number of rejected frames only).
    """
    status = np.full(len(crc_ok), _S_CRC, dtype=np.int8)
    every = bool(crc_ok.all())  # the usual case: no gather of the valid frames
    valid = None if every else np.flatnonzero(crc_ok)
    if valid is not None and len(valid) == 0:
        return status
    c = ((counter if valid is None else counter[valid]) & COUNTER_MASK).astype(np.int8)
    t = timestamp_s if timestamp_s is None or valid is None else timestamp_s[valid]
    naive = np.full(len(c), _S_OK, dtype=np.int8)
    delta = (c[1:] - c[:-1]) & COUNTER_MASK  # int8: 0..15, the step mod 16
    cum_valid = None if valid is None else np.cumsum(periods)[valid]
    # periods from each valid frame to the next: its own, when every frame is valid
    window = periods[1:] + max_delta_init if cum_valid is None else (
        cum_valid[1:] - cum_valid[:-1] + max_delta_init)
    np.minimum(window, MAX_DELTA_COUNTER, out=window)
    codes = [np.int8(code) for code in (_S_OK, _S_REPEATED, _S_LOST, _S_WRONG)]
    naive[1:] = np.where(delta == 1, codes[0], np.where(
        delta == 0, codes[1], np.where(delta <= window, codes[2], codes[3])))
    bad = np.flatnonzero((naive == _S_REPEATED) | (naive == _S_WRONG))
    if len(bad) and cum_valid is None:
        cum_valid = np.cumsum(periods)
    j = 0
    while True:
        k = int(np.searchsorted(bad, j))
        if k == len(bad):
            break
        start = int(bad[k])  # its predecessor (start - 1) was accepted
        assert cum_valid is not None
        j = _rejudge(naive, c, cum_valid, start, max_delta_init, t, cycle_s)
    if valid is None:
        return naive
    status[valid] = naive
    return status


def _rejudge(
    naive: npt.NDArray[np.int8],
    c: npt.NDArray[np.int8],
    cum: npt.NDArray[np.int64],
    start: int,
    max_delta_init: int,
    t: npt.NDArray[np.float64] | None,
    cycle_s: float | None,
) -> int:
    """Re-judge valid frames (bus times ``t``, if known) from ``start`` until one is accepted
    with its window restarted (not a new COUNTER cycle); returns the next index."""
    last, last_cum = int(c[start - 1]), int(cum[start - 1])
    state = SequenceState(max_delta_init, False, last, window=max_delta_init, cycle_s=cycle_s,
                          last_valid_s=None if t is None else float(t[start - 1]))
    codes = {OK: _S_OK, OKSOMELOST: _S_LOST, REPEATED: _S_REPEATED, WRONG_SEQUENCE: _S_WRONG}
    for j in range(start, len(c)):
        result = state.check(True, int(c[j]), int(cum[j]) - last_cum,
                             None if t is None else float(t[j]))
        last_cum = int(cum[j])
        naive[j] = codes[result]
        if result in (OK, OKSOMELOST) and int(c[j]) != last:
            return j + 1
    return len(c)


# --- a whole log -------------------------------------------------------------------------------


def check_frames(
    frames: FrameArrays, db: DatabaseSpec | None = None,
    touched: list[npt.NDArray[np.intp]] | None = None, decided: dict[int, bool] | None = None,
    settle_all: bool = False, only: str | None = None,
) -> tuple[dict[str, dict[str, int]], npt.NDArray[np.bool_]]:
    """Profile 2 over every frame of a log.

    Returns the counts per message name (``E2E_KEYS``; only messages present in the log) plus an
    ``"unknown"`` section (``UNKNOWN_KEYS``), and the mask (N,) of the frames accepted (OK or
    OKSOMELOST; the frames of unprotected messages are accepted unchecked). ``db`` defaults to
    the contract (dbc/odocan.dbc). ``touched``, when given, gets the bus positions of the
    frames whose verdict of the stamps the poses or the pages changed (evidence that may come
    after the frame: ``host.judge.stream_carry``, ``stream_e2e``); ``decided`` (bus positions
    asked) says of each encoder frame whether its verdict is one by every reading of its stamp
    (``e2e_decided``); ``settle_all``: the evidence read even where every reading agrees (a live
    hold's few frames, judged as a log whose readings differ somewhere: ``e2e_halts``).
    ``only`` (a message name): that message's frames judged alone, the others' skipped (their
    counts and marks left out; a live hold asks only of its encoder frames, ``liveearly``). Its
    verdicts are the same: a message's sequence reads its own frames, the CRCs and the
    firmware's evidence (the poses' and pages' right CRCs), never another's verdicts.

    The frames are grouped by message once (a stable sort of their message numbers) and the CRCs
    of all protected frames found in one pass; the sequence is then judged per message.
    """
    db = db if db is not None else default_plan()
    configs = e2e_messages(db)
    accepted = np.zeros(len(frames), dtype=bool)
    counts: dict[str, dict[str, int]] = {}
    unknown = dict.fromkeys(UNKNOWN_KEYS, 0)
    unknown["error_frames"] = int(np.count_nonzero(frames.flags & FLAG_ERROR))
    unknown["remote_frames"] = int(
        np.count_nonzero((frames.flags & (FLAG_REMOTE | FLAG_ERROR)) == FLAG_REMOTE)
    )
    sorted_keys = tuple(sorted(configs))
    in_order = [configs[key] for key in sorted_keys]
    groups = frame_groups(frames, sorted_keys)
    of_none = groups.of(len(in_order))  # error and remote frames (key -1) among them
    unknown["unknown_id"] = int(
        np.count_nonzero((frames.flags[of_none] & (FLAG_ERROR | FLAG_REMOTE)) == 0))
    protected = [c.data_ids is not None for c in in_order]
    crc_ok = _crc_ok(frames, groups.numbers, in_order) if any(protected) else None
    poses = None if crc_ok is None else evidence_frames(
        frames, [groups.of(k) for k in range(len(in_order))],
        [(c.name, c.length) for c in in_order], crc_ok)
    pages = None if crc_ok is None else ok_pages(frames, crc_ok, db)
    for number, config in enumerate(in_order):
        of_id = groups.of(number)
        if len(of_id) == 0 or (only is not None and config.name != only):
            continue
        right_dlc = of_id[frames.dlc[of_id] == config.length]
        unknown["wrong_dlc"] += len(of_id) - len(right_dlc)
        if crc_ok is None or config.data_ids is None:
            unknown["unprotected"] += len(right_dlc)
            accepted[right_dlc] = True
            continue
        counts[config.name] = _check_message(frames, right_dlc, config, accepted, crc_ok, poses,
                                             pages, touched, decided, settle_all)
    counts[UNKNOWN] = unknown
    return counts, accepted


def _crc_ok(
    frames: FrameArrays, message: npt.NDArray[np.integer[Any]], in_order: list[E2EMessage]
) -> npt.NDArray[np.bool_]:
    """Whether each frame's byte 0 is the Profile 2 CRC of its message (its data ID picked by
    its counter; meaningless for frames of unprotected or unknown messages)."""
    data_ids = np.zeros((len(in_order) + 1, COUNTER_LAP), dtype=np.uint8)
    for number, config in enumerate(in_order):
        if config.data_ids is not None:
            data_ids[number] = config.data_ids
    counter = frames.data[:, 1] & COUNTER_MASK
    # message * COUNTER_LAP + counter: below 2048 * 16 when message is a uint16 (message_numbers)
    crc = crc8h2f_p02(frames.data, np.take(data_ids.ravel(), message * COUNTER_LAP + counter))
    ok: npt.NDArray[np.bool_] = crc == frames.data[:, 0]
    return ok


def _check_message(
    frames: FrameArrays, index: npt.NDArray[np.intp], config: E2EMessage,
    accepted: npt.NDArray[np.bool_], crc_ok: npt.NDArray[np.bool_],
    poses: list[npt.NDArray[np.intp]] | None = None, pages: OkPages | None = None,
    touched: list[npt.NDArray[np.intp]] | None = None, decided: dict[int, bool] | None = None,
    settle_all: bool = False,
) -> dict[str, int]:
    """Check the frames ``index`` of one protected message (``crc_ok``: of every frame); mark
    the accepted ones. ``poses``: the evidence frames' positions (``e2e_evidence``); ``pages``:
    the firmware's counts of the encoder frames it took (``e2e_pages``)."""
    assert config.data_ids is not None
    counter = (frames.data[index, 1] & COUNTER_MASK).astype(np.int64)
    periods = frame_periods(frames.timestamp_s[index], counter, crc_ok[index], config.cycle_s,
                            config.min_periods)
    cycle_s = new_cycle_s(config)
    t_s = frames.timestamp_s[index]
    status = sequence_statuses(crc_ok[index], counter, periods, config.max_delta_init, t_s,
                               cycle_s)
    if config.name in PER_PERIOD_WINDOW and config.cycle_s is not None and poses is not None:
        status = _settled(frames, index, counter, crc_ok[index], periods, status, config, poses,
                          pages, touched, decided, settle_all)
        counted = repeats_by_pages(status, counter, index, pages)  # e2e_repeats
        if touched is not None and counted is not status:
            touched.append(index[counted != status])
        status = counted
    good = (status == _S_OK) | (status == _S_LOST)
    if good.all():  # the usual case: no gathers
        accepted[index] = True
        valid = None
        count, steps = len(good), counter[1:] - counter[:-1]
    else:
        accepted[index[good]] = True
        valid = np.flatnonzero(good)
        count, steps = len(valid), counter[valid[1:]] - counter[valid[:-1]]
    steps &= COUNTER_MASK
    lost = int(np.sum(steps) - count + 1)
    if cycle_s is not None and count > 1:
        lost += new_cycle_frames(steps, t_s if valid is None else t_s[valid], cycle_s)
    return {
        "ok": count,
        "lost": lost if count else 0,
        "repeated": int(np.count_nonzero(status == _S_REPEATED)),
        "crc_errors": int(np.count_nonzero(status == _S_CRC)),
        "wrong_sequence": int(np.count_nonzero(status == _S_WRONG)),
        **silences(t_s if valid is None else t_s[valid], config.cycle_s),
    }


def _settled(frames: FrameArrays, index: npt.NDArray[np.intp], counter: npt.NDArray[np.int64],
             crc_ok: npt.NDArray[np.bool_], periods: npt.NDArray[np.int64],
             status: npt.NDArray[np.int8], config: E2EMessage,
             poses: list[npt.NDArray[np.intp]],
             pages: OkPages | None = None,
             touched: list[npt.NDArray[np.intp]] | None = None,
             decided: dict[int, bool] | None = None, settle_all: bool = False
             ) -> npt.NDArray[np.int8]:
    """``status`` where the capture's stamps decide every frame (not with ``settle_all``); else
    settled from the firmware's poses (``e2e_evidence``) and its counts (``e2e_pages``; a skip
    proof they contradict dropped: ``e2e_skipveto``), the bus positions of the frames where
    they change a verdict of the stamps' added to ``touched``."""
    assert config.cycle_s is not None
    t_s, cycle_s = frames.timestamp_s[index], new_cycle_s(config)
    wide, narrow = readings(t_s, counter, crc_ok, config.cycle_s, periods)
    if not settle_all and all(np.array_equal(p, periods) or np.array_equal(
            status, sequence_statuses(crc_ok, counter, p, config.max_delta_init, t_s, cycle_s))
           for p in (wide, narrow)):
        if decided is not None:
            all_decided(decided, index)
        return status
    evidence = replace(pose_evidence(frames, index, counter, crc_ok, poses),
                       beyond=beyond_bound(frames, index))  # e2e_bound
    released = recorder_releases(frames.timestamp_s, frame_keys(frames) == config.key,
                                 config.cycle_s)[index]
    def run_with(reading: npt.NDArray[np.int8] | None, proofs: Evidence
                 ) -> npt.NDArray[np.int8]:
        return settle(crc_ok, counter, (periods, wide, narrow), proofs, config.max_delta_init,
                      released, None if cycle_s is None else (t_s, cycle_s), reading)

    runs: dict[bytes | None, npt.NDArray[np.int8]] = {}  # per reading judged alike (a copy out)

    def run(reading: npt.NDArray[np.int8] | None) -> npt.NDArray[np.int8]:
        key = reading_key(reading, released)
        if key not in runs:
            runs[key] = run_with(reading, evidence)
        return runs[key].copy()

    def unread(proofs: Evidence) -> npt.NDArray[np.int8]:
        return run_with(None, proofs)

    settled = by_pages(run, run(None), index, released, pages)
    settled = by_page_skips(unread, settled, status, index, evidence, pages)  # e2e_skipveto
    if touched is not None:
        touched.append(index[settled != status])
    if decided is not None:
        by_readings(decided, index, run, settled)
    return settled
