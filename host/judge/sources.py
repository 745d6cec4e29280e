"""Who sends ODOM_STATUS: one firmware, a rebooted one, or two on one ID -- told from UPTIME.

The one detection of a firmware reboot, shared by the live monitor (``host.judge.monitor``) and
the log analysis (``host.judge.analysis``): a source's UPTIME (whole seconds) minus bus time stays
constant within ``UPTIME_MATCH_S``; a reboot moves that offset once, or sends an UPTIME below the
last one (even within ``UPTIME_MATCH_S``: a reboot a second or two after power-up), or says INIT
after running; two sources on one ID make two offsets interleave (two sources whose offsets
differ by less than ``UPTIME_MATCH_S`` look like reboots). A reboot within the first second
after the previous one that does not say INIT cannot be told from UPTIME (0 again).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from odocan.host.judge.livegapseen import heard_status
from odocan.host.judge.tracking import PoseTracker
from odocan.host.protocol.e2e import E2EMonitor, crc8h2f_p02_one

if TYPE_CHECKING:  # the live judges' (a log's analysis imports this module, not cantools)
    from cantools.database.can import Database, Message

FIRMWARE_NODE = "ODOM_MCU"  # the DBC node that sends the firmware's frames (ODOM_STATUS, ...)
UPTIME_MATCH_S = 2.0  # one source's UPTIME (whole s) minus bus time stays within this
CONFLICT_HOLD_S = 2.0  # CONFLICT is shown this long after two sources last interleaved


@dataclass
class SourceWatch:
    """One node's UPTIME against bus time, summary after summary: a single source keeps
    UPTIME - t constant (to the second), a reboot moves it once, two sources on one ID make two
    offsets interleave."""

    offset_s: float | None = None  # UPTIME - bus time of the source followed
    other_s: float | None = None  # the offset before the last change
    last_uptime_s: int = 0
    last_state: str = ""
    conflict_until_s: float = -math.inf
    first_uptime_s: int | None = None  # the first summary's UPTIME
    page_pending: bool = True  # the first life's first ENC_E2E_OK page not heard yet
    changed_at_s: float | None = None  # when the offset followed last changed to a new one
    conflict_from_s: float | None = None  # two sources: when the second offset first came

    def first_life_page(self) -> bool:
        """Called at each ENC_E2E_OK page: whether it is the first life's first and the first
        summary said UPTIME 0 (with the frames heard, a power-up's evidence:
        ``PoseTracker.on_enc_counts``). True once."""
        first, self.page_pending = self.page_pending, False
        return first and self.first_uptime_s == 0

    def observe(self, t_s: float, uptime_s: int, state: str) -> str | None:
        """One ODOM_STATUS summary; returns ``"reboot"``, ``"two sources"``, ``"uptime jump"``
        or None."""
        offset = uptime_s - t_s
        kind = None
        if self.offset_s is None:
            self.offset_s, self.first_uptime_s = offset, uptime_s
        elif abs(offset - self.offset_s) <= UPTIME_MATCH_S:
            if (state == "INIT" and self.last_state not in ("", "INIT")) or (
                uptime_s < self.last_uptime_s  # one source's UPTIME never goes back
            ):
                kind = "reboot"
                self.offset_s = offset
        elif self.other_s is not None and abs(offset - self.other_s) <= UPTIME_MATCH_S:
            kind = "two sources"
            self.conflict_until_s = t_s + CONFLICT_HOLD_S
            if self.conflict_from_s is None:  # it began when the second offset first came
                self.conflict_from_s = self.changed_at_s
            self.offset_s, self.other_s = self.other_s, self.offset_s
        else:
            kind = "reboot" if uptime_s < self.last_uptime_s or state == "INIT" else "uptime jump"
            self.offset_s, self.other_s = offset, self.offset_s
            self.changed_at_s = t_s
        self.last_uptime_s, self.last_state = uptime_s, state
        self.page_pending = self.page_pending and kind != "reboot"
        return kind

    def conflict_text(self) -> str:
        """The verdict's reason once two sources were seen (``two_sources_text``); "" before."""
        return "" if self.conflict_from_s is None else two_sources_text(self.conflict_from_s)

    def observe_quiet(
        self, t_s: npt.NDArray[np.float64], uptime_s: npt.NDArray[np.int64],
        states: npt.NDArray[np.object_],
    ) -> int:
        """``observe`` of the summaries given (bus times, UPTIMEs, STATE names, in order) up to
        the first one that ``observe`` would return something for or follow another offset at,
        which is left unobserved; returns how many were observed (all: ``len(t_s)``). The
        same state as ``observe`` one by one, vectorised (a log's summaries are mostly quiet).
        """
        if self.offset_s is None or len(t_s) == 0:
            return 0
        init = states == "INIT"
        idle = init | (states == "")  # a state after which INIT is no reboot
        before_uptime_s = np.concatenate(([self.last_uptime_s], uptime_s[:-1]))
        before_idle = np.concatenate(([self.last_state in ("", "INIT")], idle[:-1]))
        loud = (
            ~(np.abs((uptime_s - t_s) - self.offset_s) <= UPTIME_MATCH_S)
            | (init & ~before_idle)
            | (uptime_s < before_uptime_s)
        )
        count = int(np.argmax(loud)) if loud.any() else len(t_s)
        if count:
            self.last_uptime_s, self.last_state = int(uptime_s[count - 1]), str(states[count - 1])
        return count


def two_sources_text(t_s: float) -> str:
    """Why a verdict FAILs when two firmwares answered on one node ID from bus time ``t_s``."""
    return f"two firmwares answered on one node ID from t={t_s:.3f} s: the pose cannot be judged"


def boot_summary(message: Message, data: bytes, data_ids: Any) -> tuple[int, str] | None:
    """(UPTIME s, STATE) of an ODOM_STATUS summary whose CRC holds, whatever its E2E sequence
    (a rebooted firmware restarts it); ``data_ids``: the message's E2E DataIDs. None otherwise."""
    if message.name != "ODOM_STATUS" or len(data) != 8:
        return None
    if not data_ids or data[0] != crc8h2f_p02_one(data, data_ids[data[1] & 0xF]):
        return None
    try:
        signals = message.decode(data)
    except Exception:  # not decodable: the E2E check and the caller count it
        return None
    assert isinstance(signals, dict)
    values: dict[str, Any] = dict(signals)
    if str(values.get("PAGE")) != "SUMMARY":
        return None
    return int(values["UPTIME"]), str(values["STATE"])


def status_frame(tracker: PoseTracker, message: Message, data: bytes, e2e: Any, t_s: float
                 ) -> tuple[int, str] | None:
    """Any ODOM_STATUS frame heard at bus time ``t_s``, whatever its E2E sequence (``e2e``: the
    message's ``E2EMessage`` or None): each page to the live gapseen
    (``livegapseen.heard_status``); a summary's ``boot_summary``."""
    data_ids = e2e.data_ids if e2e is not None else None
    heard_status(tracker, message, data, data_ids, t_s)
    return boot_summary(message, data, data_ids)


def start_new_life(tracker: PoseTracker, e2e: E2EMonitor, db: Database,
                   uptime_s: int, state: str) -> str:
    """A reboot told by ``SourceWatch``: the reference starts at the power-up pose when the
    summary says UPTIME 0 (``PoseTracker.power_up``; ``host.judge.reboots``), else (more than a
    second after the boot: its page of encoder E2E counts may be gone too) at the next pose;
    the E2E sequences of the messages ``FIRMWARE_NODE`` sends in ``db`` start afresh (a reboot
    is not frames lost). Returns what was done (text)."""
    tracker.placer.seen.new_life()  # its pages count from 0 (host.judge.livegapseen)
    for message in db.messages:
        if FIRMWARE_NODE in message.senders:  # the counts stay; the next frame starts afresh
            e2e.restart_sequence(message.frame_id, extended=message.is_extended_frame)
    if uptime_s == 0:
        tracker.power_up(primed_now=state != "INIT")
        return "reference restarted at the power-up pose"
    tracker.new_life()
    return "reference restarted"
