"""Two sources on one ID told live from the firmware's pose frames (issue #11), as the log's
judge tells them (``host.judge.posestreams``, whose docstring has the rule): the monitor and the
bridge feed each CRC-right ODOM_POSE_X frame, whatever its E2E sequence, to the
``SourceWatch``'s ``LiveStreams`` (``hear``); from the first window of ``WINDOW_FRAMES`` frames of
one message holding ``SIGNATURES``, the watch is in conflict from that window's first signature
(``SourceWatch.conflict_from_s``: no pose judged from there, CONFLICT while they interleave,
the end verdict a FAIL with ``detail``). Per frame in plain Python: a few comparisons, for the
bridge's fleets (``SenderWatch._signature``'s rule, which this mirrors)."""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING, Any, Final

if TYPE_CHECKING:
    from odocan.host.judge.sources import SourceWatch
    from odocan.host.judge.tracking import PoseTracker

WATCHED: Final = ("ODOM_POSE_X",)  # the pose message the judges watch (X and HEADING)
WINDOW_FRAMES: Final = 32  # CRC-right frames of one message looked over
SIGNATURES: Final = 12  # signatures within the window that no one sender makes (two make ~16;
# one sender's late frames reordered on the bus, ``--faults delay``, made 4 within 16)
RECENT: Final = 4  # frames before the previous one a frame may continue (twosenders.RECENT)
COUNTER_MASK: Final = 0x0F  # the Profile 2 COUNTER (byte 1, low nibble)
CONFLICT_HOLD_S: Final = 2.0  # CONFLICT shown this long after the last window (sources')


def detail_text(message: str, t_s: float) -> str:
    """The verdict's reason: two streams of ``message`` from bus time ``t_s``."""
    return (f"two sources on one ID: two {message} streams interleave from t={t_s:.3f} s: "
            "whose pose each frame is cannot be told, the pose cannot be judged")


def signature(recent: deque[bytes], data: bytes) -> bool:
    """Whether ``data`` shows a second sender after the ``recent`` frames (module docstring)."""
    if not recent or len(data) < 2:
        return False
    counter, previous = data[1] & COUNTER_MASK, recent[-1]
    before = previous[1] & COUNTER_MASK
    if counter == before:
        return data != previous  # a duplicate of one frame is one sender
    if counter == (before + 1) & COUNTER_MASK:
        return False
    return any(counter == ((f[1] & COUNTER_MASK) + 1) & COUNTER_MASK
               for f in list(recent)[:-1])


class LiveStreams:
    """The watch over the pose messages' CRC-right frames, one at a time."""

    def __init__(self) -> None:
        self._recent: dict[str, deque[bytes]] = {}
        self._marks: dict[str, deque[tuple[int, float]]] = {}  # the latest signatures
        self._heard: dict[str, int] = {}

    def hear(self, message: str, data: bytes, t_s: float) -> float | None:
        """A CRC-right frame of ``message`` at bus time ``t_s``: the bus time of the first
        signature of the window it fills (two sources from then), else None."""
        recent = self._recent.setdefault(message, deque(maxlen=RECENT + 1))
        n = self._heard[message] = self._heard.get(message, 0) + 1
        marked = signature(recent, bytes(data))
        recent.append(bytes(data))
        if not marked:
            return None
        marks = self._marks.setdefault(message, deque(maxlen=SIGNATURES))
        marks.append((n, t_s))
        if len(marks) == SIGNATURES and n - marks[0][0] < WINDOW_FRAMES:
            return marks[0][1]
        return None


def hear_pose_frame(watch: SourceWatch, message: str, data: bytes, t_s: float,
                    tracker: PoseTracker | None = None, events: Any = None) -> None:
    """A CRC-right pose frame for ``watch``'s streams; when it tells two sources: the watch's
    conflict (from the window's first signature, unless UPTIME told one earlier; CONFLICT held
    on), no pose judged from there (``tracker.wrongs.unjudgeable_from``), one ``two sources``
    event in ``events`` while it lasts (the monitor's; default the tracker's)."""
    from_s = watch.streams.hear(message, data, t_s)
    if from_s is None:
        return
    if watch.conflict_from_s is None or from_s < watch.conflict_from_s:  # the earlier telling
        watch.conflict_from_s, watch.conflict_detail = from_s, detail_text(message, from_s)
    watch.conflict_until_s = t_s + CONFLICT_HOLD_S
    if tracker is not None:
        tracker.wrongs.unjudgeable_from(watch.conflict_from_s)
        events = events if events is not None else tracker.restarts.events
    if events is None:
        return
    last = events[-1] if events else None
    if last and last["kind"] == "two sources" and t_s - last["t_s"] < CONFLICT_HOLD_S:
        last["t_s"] = t_s  # one event while the conflict lasts
        return
    events.append({"t_s": t_s, "kind": "two sources", "detail": watch.conflict_detail
                   or detail_text(message, from_s)})
