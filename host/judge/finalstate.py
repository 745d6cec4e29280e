"""The firmware's final state (issue #11): what its last accepted ODOM_STATUS summary said and
since when, for the report's ``firmware_final`` and the text summary's ``firmware`` line.

A run may PASS while the firmware ends DEGRADED (POSE_UNCERTAIN and COUNTER_RESET are latched
until a set-pose): ``firmware_events`` says so, the summary must too. Read from the same
``StatusLatch`` that made the events (``host.judge.statuslatch``), whole and streamed alike; a
reboot starts a fresh latch, so the final state is the last firmware life's.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from odocan.host.judge.reasonwords import REASON_WORDS
from odocan.host.judge.statuslatch import StatusLatch, firmware_events
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import check_frames

if TYPE_CHECKING:
    from odocan.host.io.logs import FrameArrays
    from odocan.host.judge.reboots import Life
    from odocan.host.protocol.dbcplan import DatabaseSpec


def final_state(latch: StatusLatch) -> dict[str, Any] | None:
    """``firmware_final``: STATE and REASON of the last summary ``latch`` observed and the bus
    time (s) of the first summary that said both; None before any summary."""
    if latch.state is None:
        return None
    return {"state": latch.state, "reason": latch.reason, "since_s": latch.since_s}


def latched_fields(events: list[dict[str, Any]], latch: StatusLatch) -> dict[str, Any]:
    """The report's ``firmware_events`` (``events``, made by ``latch``) and ``firmware_final``."""
    return {"firmware_events": events, "firmware_final": final_state(latch)}


def firmware_fields(frames: Any, accepted: npt.NDArray[np.bool_], decoder: Any
                    ) -> dict[str, Any]:
    """``latched_fields`` of a fresh latch over ``frames`` (``statuslatch.firmware_events``)."""
    latch = StatusLatch()
    return latched_fields(firmware_events(frames, accepted, decoder, latch), latch)


def final_text(final: dict[str, Any] | None, origin_s: float = 0.0) -> str | None:
    """The summary's words for ``final`` when the firmware ends not OK, e.g. ``ends DEGRADED
    POSE_UNCERTAIN since 4.05 s: ... until a set-pose``, its time in seconds since ``origin_s``
    (the log's first frame: ``host.report.logtime``; the report's ``since_s`` is bus time);
    None when it ends OK (or said nothing)."""
    if not final or final["state"] == "OK":
        return None
    since = "" if final["since_s"] is None else f" since {final['since_s'] - origin_s:.2f} s"
    words = REASON_WORDS.get(str(final["reason"]))
    return f"ends {final['state']} {final['reason']}{since}" + (f": {words}" if words else "")


def latched_per_firmware(frames: FrameArrays, lives: list[Life],
                         db: DatabaseSpec) -> dict[str, Any]:
    """``firmware_events`` of each firmware life (a reboot's), its mask latched from its start
    (a set-pose's cut does not clear the firmware's sticky bits: not reported again there), and
    the last life's ``firmware_final``."""
    events: list[dict[str, Any]] = []
    latch = StatusLatch()
    for k, life in enumerate(lives):
        part = frames.select(life.index)
        latch = StatusLatch()  # a reboot clears the firmware's state
        events += [dict(e, firmware_life=k) for e in firmware_events(
            part, check_frames(part, db)[1], BulkDecoder(db), latch)]
    return latched_fields(events, latch)
