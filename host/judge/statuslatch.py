"""The firmware's own reports latched into events (issue #11): every ERROR_MASK bit newly set and
every STATE change seen in ODOM_STATUS summaries, with its bus time and its name.

The firmware's DEGRADED for TIME_LOST lasts 50 ms and the summary goes out every 100 ms, so a
summary may never say DEGRADED; the sticky ERROR_MASK keeps the bit, and the host latches it
here the first time it sees it set. The same ``StatusLatch`` serves the monitor model
(``host.judge.monitor``: ``firmware_events``), the MQTT bridge (``host.mqtt.telemetry``: its
retained ``status`` carries the latest events and ``latched_errors``) and ``analyze`` (the
report's ``firmware_events``, whole and streamed: ``latch_summaries`` over a page's decoded
columns), so they say the same things.

Kept apart from the judge's own events (reboots, stalls, set-pose, losses), which say what the
host did with the reference; these say what the firmware reported. A bit the firmware clears
(a reboot, COUNTER_RESET cleared by a set-pose) is forgotten: set again, it is latched again.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from odocan.firmware.errors import ErrorFlag
from odocan.host.judge.reasonwords import reason_text
from odocan.host.protocol import busfacts
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.protocol.decode import DecodeError

SUMMARY_PAGE = busfacts.SUMMARY_PAGE  # ODOM_STATUS page with STATE, REASON and ERROR_MASK
_BIT_NAMES = {int(flag).bit_length() - 1: str(flag.name) for flag in ErrorFlag if flag}
_STATUS = default_plan().get_message_by_name("ODOM_STATUS")  # enum names: the DBC's VAL_
_STATES = {int(v): str(n) for v, n in (_STATUS.get_signal_by_name("STATE").choices or {}).items()}
_REASONS = {int(v): str(n)
            for v, n in (_STATUS.get_signal_by_name("REASON").choices or {}).items()}


def bit_name(bit: int) -> str:
    """The ``ErrorFlag`` name of ERROR_MASK bit ``bit`` (``BIT<n>`` when unnamed)."""
    return _BIT_NAMES.get(bit, f"BIT{bit}")


class StatusLatch:
    """The last summary's STATE and ERROR_MASK; ``observe`` returns what changed as events."""

    def __init__(self) -> None:
        self.state: str | None = None  # None before the first summary
        self.reason: str | None = None  # ... its REASON
        self.since_s: float | None = None  # bus time of the first summary saying both
        self.mask = 0
        self.latched = 0  # every bit ever seen set (for a status that shows them all)

    def observe(self, t_s: float, state: int, reason: int, mask: int) -> list[dict[str, Any]]:
        """One accepted ODOM_STATUS summary (raw STATE, REASON, ERROR_MASK; bus time s): the
        events it brings, state change first, then the bits newly set, lowest first."""
        name, why = _STATES.get(state, str(state)), _REASONS.get(reason, str(reason))
        events: list[dict[str, Any]] = []
        if self.state is not None and name != self.state:
            events.append({"t_s": t_s, "kind": "state", "state": name, "reason": why,
                           "detail": f"state {self.state} -> {name} (reason {reason_text(why)})"})
        if (name, why) != (self.state, self.reason):
            self.since_s = t_s
        self.state, self.reason = name, why
        new = mask & ~self.mask
        self.mask = mask
        self.latched |= mask
        bit = 0
        while new >> bit:
            if new >> bit & 1:
                events.append({"t_s": t_s, "kind": "error_bit", "bit": bit_name(bit),
                               "detail": f"ERROR_MASK {bit_name(bit)} set (state {name}, "
                                         f"reason {reason_text(why)})"})
            bit += 1
        return events

    def latched_names(self) -> list[str]:
        """The names of every ERROR_MASK bit seen set so far."""
        return [bit_name(b) for b in range(self.latched.bit_length()) if self.latched >> b & 1]


def latch_summaries(latch: StatusLatch, page: dict[str, np.ndarray],
                    keep: npt.NDArray[np.bool_]) -> list[dict[str, Any]]:
    """``latch`` fed the accepted (``keep``) rows of a decoded ODOM_STATUS summary page
    (``BulkDecoder.decode_page``'s columns: STATE, REASON, ERROR_MASK, timestamp_s); one
    Python step per summary (10 a second), only where one changed anything."""
    if not len(page["index"]) or not {"STATE", "REASON", "ERROR_MASK"} <= page.keys():
        return []
    state, reason = page["STATE"][keep].astype(np.int64), page["REASON"][keep].astype(np.int64)
    mask, t_s = page["ERROR_MASK"][keep].astype(np.int64), page["timestamp_s"][keep]
    if not len(state):
        return []
    # the first row, and every row unlike the one before (a row like it changes nothing: the
    # latch holds its values already)
    changed = np.ones(len(state), dtype=bool)
    changed[1:] = (state[1:] != state[:-1]) | (mask[1:] != mask[:-1]) | (
        reason[1:] != reason[:-1])
    events: list[dict[str, Any]] = []
    for k in np.flatnonzero(changed).tolist():
        events += latch.observe(float(t_s[k]), int(state[k]), int(reason[k]), int(mask[k]))
    return events


def firmware_events(frames: Any, accepted: npt.NDArray[np.bool_], decoder: Any,
                    latch: StatusLatch | None = None) -> list[dict[str, Any]]:
    """``analyze``'s ``firmware_events``: ``latch`` (default a fresh ``StatusLatch``) over the
    accepted ODOM_STATUS summaries of ``frames`` (``FrameArrays``; ``decoder``: a
    ``BulkDecoder``); none when the DBC's ODOM_STATUS has no summary page."""
    try:
        page = decoder.decode_page(frames, "ODOM_STATUS", SUMMARY_PAGE)
    except (DecodeError, KeyError):
        return []
    latch = latch if latch is not None else StatusLatch()
    return latch_summaries(latch, page, accepted[page["index"]])
