"""Two senders on one command message (issue #11: "two sources on one ID are reported"): two
tools commanding one robot, e.g. an ``odocan bridge`` answering ``cmd/config`` and an
operator's script, each with its own Profile 2 COUNTER sequence on ODOM_CONFIG, ODOM_SET_POSE
or NAV_GOAL (``COMMANDS``: all three are staged writes committed by a last frame, APPLY or GO).

Why it matters: the firmware's receiver (firmware/reception.py) drops a frame whose COUNTER
repeats the last one it accepted (E2E REPEATED) and answers nothing, so the second tool's
command is lost without a word; ODOM_ACK names a request only by its CAN ID, COUNTER and
multiplexer value, so each tool may take the other's answers for its own; and both tools'
staged writes go into one staged set, so one tool's APPLY (GO) commits the other's parameters
(pose fields, goal).

``SenderWatch`` reads the CRC-right frames of one message in bus order (the monitor hears
every one; ``analyze`` reads the log) and tells two senders by one of two signatures, neither
of which one sender can make (a sender's COUNTER only goes up, +1 a frame, mod 16):

* **a repeat with other content**: the COUNTER of the previous frame again, other bytes (one
  sender repeats a COUNTER only in a duplicate of the same frame, or after 16 frames lost in a
  row, or when it restarted: the reason says so);
* **interleaved sequences**: a frame continuing (+1) one of the ``RECENT`` frames before the
  previous one, but not the previous one, twice within ``LAP_FRAMES`` frames heard (one
  sender makes it once when its COUNTER laps: 17 - m frames lost over the m gaps between the
  two, at least 12 within ``RECENT`` + 1 frames; twice, only when it laps twice so; two
  tools' configs interleaved make it at nearly every frame).

The bridge, which does not hear its own frames back, tells it differently
(``host.mqtt.livecommands``: another tool's frame heard while its own command is in flight).
"""

from __future__ import annotations

from collections import deque
from collections.abc import MutableSequence
from typing import TYPE_CHECKING, Any, Final

import numpy as np

from odocan.host.io.frames import FLAG_ERROR, FLAG_EXTENDED, FLAG_REMOTE, FrameArrays
from odocan.host.protocol.e2e import e2e_messages
from odocan.host.protocol.e2e_crc import crc8h2f_p02_one

if TYPE_CHECKING:  # a cantools Database or the judge's plan of it (no cantools when cached)
    from odocan.host.protocol.dbcplan import DatabaseSpec

COUNTER_MASK: Final = 0x0F  # the E2E Profile 2 COUNTER (byte 1, low nibble)
RECENT: Final = 4  # frames looked back on for an interleaved sequence
HOLD_S: Final = 1.0  # one event while the signature keeps coming, at most one a second
LAP_FRAMES: Final = 16  # two interleaving signatures within this many frames are told
FRAME_BYTES: Final = 8  # a Profile 2 frame
NOT_A_STANDARD_DATA_FRAME: Final = FLAG_EXTENDED | FLAG_REMOTE | FLAG_ERROR
INTERLEAVED: Final = "interleaved COUNTER sequences"
COMMANDS: Final = {"ODOM_CONFIG": "APPLY", "ODOM_SET_POSE": "APPLY", "NAV_GOAL": "GO"}  # watched
# messages: the frame that commits the staged set


class SenderWatch:
    """Two senders on the message ``name`` (module docstring): ``heard`` each CRC-right frame
    (accepted or refused REPEATED / WRONGSEQUENCE), in bus order; ``count`` the signatures."""

    def __init__(self, name: str) -> None:
        self.name = name
        self._commit = COMMANDS.get(name, "APPLY")  # the frame committing the staged set
        self.count = 0  # frames showing a second sender
        self._recent: deque[bytes] = deque(maxlen=RECENT + 1)  # the latest frames, oldest first
        self._heard = 0  # frames heard
        self._interleaved_at = -LAP_FRAMES  # the frame number of the latest interleaving one
        self._said_s = -HOLD_S

    def heard(self, data: bytes, t_s: float) -> str | None:
        """A CRC-right frame of the message at bus time ``t_s`` (s); the event's detail when
        it shows a second sender and none was said in the last ``HOLD_S``, else None."""
        why = self._signature(bytes(data))
        self._recent.append(bytes(data))
        self._heard += 1
        if why is None:
            return None
        self.count += 1
        if why.startswith(INTERLEAVED):
            first, self._interleaved_at = self._interleaved_at, self._heard
            if self._heard - first > LAP_FRAMES:
                return None  # once: one sender whose COUNTER lapped (module docstring)
        if t_s - self._said_s < HOLD_S:
            return None
        self._said_s = t_s
        return f"two senders on {self.name}: {why}"

    def _signature(self, data: bytes) -> str | None:
        if not self._recent or len(data) < 2:
            return None
        counter = data[1] & COUNTER_MASK
        previous = self._recent[-1]
        before = previous[1] & COUNTER_MASK
        if counter == before:
            if data == previous:
                return None  # a duplicate of one frame (CAN's double reception): one sender
            return (f"COUNTER {counter} repeated with other content: the firmware drops the "
                    "second frame unanswered (E2E REPEATED; or one sender restarted its COUNTER)")
        if counter == (before + 1) & COUNTER_MASK:
            return None
        earlier = [f[1] & COUNTER_MASK for f in list(self._recent)[:-1]]
        if any(counter == (c + 1) & COUNTER_MASK for c in earlier):
            sequence = ", ".join(str(c) for c in [*earlier, before, counter])
            return (f"{INTERLEAVED} ({sequence}): their staged writes mix in one staged set, "
                    f"and each {self._commit} commits the other's")
        return None


class CommandSenders:
    """A ``SenderWatch`` for each of ``COMMANDS`` the DBC has, by CAN ID (the monitor's)."""

    def __init__(self, db: DatabaseSpec) -> None:
        self.watches = {m.frame_id: SenderWatch(m.name) for m in db.messages
                        if m.name in COMMANDS}

    def heard(self, can_id: int, data: bytes, t_s: float) -> str | None:
        """A CRC-right frame of a watched message (``SenderWatch.heard``); None for others."""
        watch = self.watches.get(can_id)
        return None if watch is None else watch.heard(data, t_s)

    def told(self, events: MutableSequence[dict[str, Any]], can_id: int, data: bytes,
             t_s: float) -> None:
        """``heard``, a second sender's signature appended to ``events`` as a ``two senders``
        event (the monitor's)."""
        detail = self.heard(can_id, data, t_s)
        if detail is not None:
            events.append({"t_s": t_s, "kind": "two senders", "detail": detail})


class LogSenders:
    """``analyze``'s ``two senders`` watch over a log read in chunks (whole, or streamed): a
    ``SenderWatch`` per message of ``COMMANDS`` the DBC protects, fed each chunk's CRC-right
    8-byte frames of it in bus order; ``events`` by bus time."""

    def __init__(self, db: DatabaseSpec) -> None:
        self._messages = {m.key: (SenderWatch(m.name), m.data_ids)
                          for m in e2e_messages(db).values()
                          if m.name in COMMANDS and m.data_ids is not None}
        self._keys = np.array(sorted(self._messages), dtype=np.int64)
        self._events: list[dict[str, Any]] = []

    def feed(self, frames: FrameArrays) -> None:
        """The next chunk of the log."""
        rows = np.flatnonzero(np.isin(frames.can_id, self._keys) & (frames.dlc == FRAME_BYTES)
                              & ((frames.flags & NOT_A_STANDARD_DATA_FRAME) == 0))
        for row in rows.tolist():
            watch, data_ids = self._messages[int(frames.can_id[row])]
            data = bytes(frames.data[row])
            if crc8h2f_p02_one(data, data_ids[data[1] & COUNTER_MASK]) != data[0]:
                continue
            t_s = float(frames.timestamp_s[row])
            detail = watch.heard(data, t_s)
            if detail is not None:
                self._events.append({"kind": "two senders", "t_s": t_s, "detail": detail})

    @property
    def events(self) -> list[dict[str, Any]]:
        return list(self._events)


def log_events(frames: FrameArrays, db: DatabaseSpec) -> list[dict[str, Any]]:
    """``analyze``'s ``two senders`` events of a whole log (``LogSenders``)."""
    senders = LogSenders(db)
    senders.feed(frames)
    return senders.events
