"""ODOM_SET_POSE followed by the live judge (issue #11; ``host.judge.tracking``): an applied
set-pose is the on-board pose's new origin, as a reboot's power-up pose is.

The firmware (firmware/commands.py) stages X, Y and HEADING frames it accepted (ACK), and APPLY
overwrites its pose with the staged fields, keeping the others (TURNS start again at 0: the
heading is then within [0, 2 pi)). It acts on a frame when it drains it from its mailbox, in bus
order, after the encoder frames heard before it (with SecOC, when its ODOM_AUTH arrives), and
answers it with ODOM_ACK. So ``SetPoseFollower`` stages a field when its ACK is heard, notes the
latest accepted encoder frame when the APPLY (or its ODOM_AUTH) is heard, and on the APPLY's
ACK (RESULT ACK) ``apply_set_pose`` restarts the reference there: at the staged fields, the
others carried from the reference at that frame (what the firmware kept, if it was right), the
encoder frames since stepped again; the truth is compared in the new frame from the next truth
sample on (``livetruth.LifeTruth``, as after a reboot). A NACKed APPLY changes nothing. A reboot
empties the firmware's staging (RAM): ``forget`` at every reboot the judge sees. Without
the reference at that frame (not started, or out of the window) the reference restarts at the
next on-board pose, as before.

Nor are the kept fields taken from the reference when it is not yet placed where the firmware
is (``unplaced``): a stall, hold or gap before the APPLY whose placement is owed, or a silence
since the last sample compared that the stall rule has not told yet. There the firmware took
the frames it missed as merged steps, and the reference, stepped through them one by one, lies
up to the merge's error from it (kobuki, a 150 ms stall, a bare APPLY the tick after it:
0.17 mm, a correct firmware latched POSE WRONG for good; ``analyze`` fits the life's start
instead). The reference restarts at the next on-board pose, as ``analyze``'s fitted start, the
first one after the silence left out (it may name a backlog frame: ``livestall``); what the
APPLY kept is judged by ``livekept`` across the stall, its bound widened by the merge's. But
a bare APPLY while the placement after a stall before the life's first sample is owed
(``owed_first``; ``livekept`` cannot judge it: no pose before it) carries the reference and the
placement owed from the frame the firmware could first have primed on (the pose is kept: the
next sample is placed as it would have been without the APPLY): a firmware that moved its X by
1 m there was adopted, OK (``tests/test_set_pose_after_first_stall.py``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from odocan.host.judge.liveadopted import MERGED_SET_POSE, UNHEARD_SET_POSE
from odocan.host.judge.livefit import LiveFit
from odocan.host.judge.livepose import FramePose
from odocan.host.judge.livestart import start_reference
from odocan.host.judge.livewindow import held_on_time, window_counts

if TYPE_CHECKING:
    from odocan.host.judge.tracking import PoseTracker

FIELDS = ("X", "Y", "HEADING")  # ODOM_SET_POSE's staged fields (FIELD's names in the DBC)
_TURN = 2.0 * math.pi


class SetPoseFollower:
    """The staged fields and the pending APPLY of ODOM_SET_POSE as the bus shows them."""

    def __init__(self, *, bus_order: bool = True) -> None:
        # ``bus_order``: the frames come in the order the firmware takes them (the monitor's,
        # analyze's); False for the bridge, which follows its own frames when it sends them:
        # two frames of one COUNTER waiting then, it cannot tell which the firmware took (it
        # drops the second on the bus unanswered, E2E REPEATED), so the APPLY is ``doubtful``
        self.bus_order = bus_order
        self._doubt = False  # two unlike frames of one COUNTER waited since the last APPLY
        self.doubtful = False  # the APPLY ACKed last was so: its pose not known to the host
        self.staged: dict[str, float] = {}  # X m, Y m, HEADING rad, as ACKed
        self._staged_s: dict[str, float] = {}  # field: bus time of its ACK (s)
        self._sent: dict[int, tuple[str, float]] = {}  # by E2E COUNTER: field, value heard
        # the APPLYs heard, not answered yet: COUNTER -> the encoder seq then (a paced burst has
        # several in flight: one slot let a later APPLY hide an earlier one's ACK)
        self._applies: dict[int, int] = {}

    def forget(self, since_s: float = math.inf) -> None:
        """A firmware reboot the judge saw: the firmware lost its staged fields and the frames
        it had not answered with its RAM (a bare APPLY after it keeps the firmware's pose);
        ``since_s``: the fields ACKed from this bus time on (s) are the new firmware's, drained
        in its first tick before its boot summary told the reboot (``liveconfig.SAME_TICK_S``),
        kept with the frames not answered yet (default: everything forgotten)."""
        if since_s == math.inf:
            self._sent, self._applies, self._doubt = {}, {}, False
        self.staged = {f: v for f, v in self.staged.items() if self._staged_s[f] >= since_s}
        self._staged_s = {f: self._staged_s[f] for f in self.staged}

    def on_frame(self, counter: int, field: str, value: float | None, enc_seq: int) -> None:
        """An ODOM_SET_POSE frame heard (its E2E COUNTER, FIELD name, value in m or rad);
        ``enc_seq``: the latest accepted encoder frame's seq."""
        before = self._sent.pop(counter, None)  # a COUNTER heard again: its older frame is gone
        apply_before = self._applies.pop(counter, None)
        if not self.bus_order:  # two unlike frames of one COUNTER: which one taken unknown
            earlier = ("APPLY", None) if apply_before is not None else before
            heard = (field, None if value is None or field == "APPLY" else float(value))
            self._doubt |= earlier is not None and earlier != heard
        if field == "APPLY":
            self._applies[counter] = enc_seq
        elif field in FIELDS and value is not None:
            self._sent[counter] = (field, float(value))

    def on_auth(self, enc_seq: int) -> None:
        """An ODOM_AUTH naming ODOM_SET_POSE: the firmware acts on the held frame now."""
        if self._applies:  # the latest APPLY is the held one
            self._applies[next(reversed(self._applies))] = enc_seq

    def on_ack(self, request_counter: int, acked: bool, t_s: float = 0.0
               ) -> tuple[int, dict[str, float]] | None:
        """ODOM_ACK of an ODOM_SET_POSE frame at bus time ``t_s``: a field ACKed is staged; the
        APPLY's ACK returns (the encoder seq it took effect after, the staged fields) and clears
        them."""
        sent = self._sent.pop(request_counter, None)
        if sent is not None and acked:
            self.staged[sent[0]] = sent[1]
            self._staged_s[sent[0]] = t_s
            return None
        seq = self._applies.pop(request_counter, None)
        if seq is None:
            return None
        staged = self.staged
        if not acked:
            return None
        self.staged, self._staged_s = {}, {}
        self.doubtful, self._doubt = self._doubt, False
        return seq, staged


def apply_set_pose(tracker: PoseTracker, seq: int, staged: dict[str, float],
                   doubt: str | None = None) -> FramePose | None:
    """Restart ``tracker``'s reference at the set pose at encoder frame ``seq`` (module
    docstring); returns that pose, None when it restarts at the next on-board pose instead
    (also when ``doubt`` says why the pose set is not known: two senders' frames)."""
    at = tracker.raw.at.get(seq)  # the raw reference at that frame (livereference)
    counts = window_counts(tracker.window, seq)
    ref_known = tracker.raw.odometry is not None and tracker.integrator is not None
    merged = ref_known and unplaced(tracker, seq) and any(n not in staged for n in FIELDS)
    first_owed = owed_first(tracker) if merged and not staged else None
    silence_from_s = tracker.stall.last_t_s
    tracker.new_life()  # the reference restarts, the truth is compared in the new frame
    if all(name in staged for name in FIELDS):  # nothing kept of a pose adopted before
        tracker.placer.dark.new_life()  # (host.judge.livedark: the OK no longer names it)
        tracker.adopted.new_life()  # (host.judge.liveadopted)
    if doubt is not None or at is None or not ref_known or not counts or counts[0][0] != seq:
        if all(name in staged for name in FIELDS):  # an offset before it overwritten whole
            tracker.wrongs.new_life(tracker.now_s)
        tracker.adopted.owe(doubt or UNHEARD_SET_POSE)  # the next on-board pose adopted
        return None
    if merged and first_owed is None:  # the kept fields where merged steps put them: the
        # next pose after the silence
        tracker.stall.carry_silence(silence_from_s)
        tracker.adopted.owe(MERGED_SET_POSE)
        return None
    tracker.wrongs.new_life(tracker.now_s)  # fields kept from the reference: still judged
    tracker.adopted.cancel()  # the set pose is where it starts, not the firmware's
    pose = FramePose(seq, staged.get("X", at.x_m), staged.get("Y", at.y_m),
                     staged.get("HEADING", at.heading_rad % _TURN))
    start_reference(tracker, pose, counts, [], first_owed)  # a placement owed: still owed
    if all(name in staged for name in ("X", "Y", "HEADING")):
        tracker.fit = LiveFit(pose.x_m, pose.y_m, exact=True)  # the pose set: nothing to fit
        tracker.cut.arm(pose)  # just after a long stall (livecutreprime)
    return pose


def owed_first(tracker: PoseTracker) -> int | None:
    """The frame the firmware could first have primed on when the placement owed is the one
    after a stall before its life's first sample (``livefirst``: none compared since), else
    None: a bare APPLY keeps the pose, so that placement is still owed after it, from there."""
    stall, primed = tracker.stall, tracker.first.stalled_from
    return primed if stall.place_at_next and stall.last_compared == primed else None


def unplaced(tracker: PoseTracker, seq: int) -> bool:
    """Whether the reference at encoder frame ``seq`` may lie beyond the fit from the firmware's
    pose (module docstring): a placement owed (a stall, hold or gap before it, an allowance
    withdrawn), or ``SILENCE_CYCLES`` frames on time since the last sample compared."""
    stall = tracker.stall
    last = stall.last_compared
    return (stall.place_at_next or tracker.placer.due(seq)
            or (0 <= last < seq and held_on_time(tracker.window, last, seq)))


def set_pose_event(t_s: float, pose: FramePose | None, staged: dict[str, Any]) -> dict[str, Any]:
    """The ``set_pose`` event: bus time of the ACK, the pose set (None fields: not known)."""
    if pose is None:
        return {"t_s": t_s, "kind": "set_pose", "x_m": staged.get("X"), "y_m": staged.get("Y"),
                "heading_rad": staged.get("HEADING"), "encoder_frame": None,
                "detail": "set pose applied: reference restarted at the next on-board pose"}
    return {"t_s": t_s, "kind": "set_pose", "x_m": pose.x_m, "y_m": pose.y_m,
            "heading_rad": pose.heading_rad, "encoder_frame": pose.seq,
            "detail": f"set pose applied (x {pose.x_m:.4f} m, y {pose.y_m:.4f} m, heading "
                      f"{pose.heading_rad:.5f} rad): the reference restarts there, the truth "
                      "is compared in the new frame"}
