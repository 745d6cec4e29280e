"""Command pacing per robot: a window of command frames in flight, the rest queued (bounded).

A burst of commands sent at once (the MQTT trial: 16 and more ``cmd/set_pose`` published
together) overflowed the firmware's receive mailbox (``MAILBOX_SLOTS`` = 32 frames, drained
once a tick): encoder frames were lost (MAILBOX_OVERFLOW) and, with more than 16 frames of one
CAN id in flight, an ODOM_ACK (matched by CAN id and 4-bit COUNTER) could answer the wrong
command while others stayed pending forever.

``CommandPacer`` sends a robot's command frames in order, at most ``window_frames`` frames on
the bus not yet answered by their ODOM_ACK (an ODOM_AUTH counts as a frame: it takes a mailbox
slot). The firmware answers every frame it drains in the tick that drains it, so the frames
the bridge adds to the mailbox between two ticks are at most the window (8 of 32 slots leave
room for a tick's encoder frames and a stall's backlog), and fewer than 16 frames of one CAN id
are ever un-answered: each COUNTER in flight is distinct. Commands beyond the window wait in a
queue of ``max_queued`` commands; beyond that a command is refused (``rejected``, said why).
Every command taken gets exactly one final answer: ``acked``/``nacked`` (the firmware's, from
``RobotTelemetry``; ``contested`` when another tool's frames of its message were heard in its
flight: the ACK may be the other's; ``unanswered`` when its last frame was ACKed but not all
its staged ones), ``expired`` (it waited in the queue longer than
``expiry_s``), ``rejected`` (the bus refused a frame), ``timeout`` (no ODOM_ACK within
``ack_timeout_s`` of its last frame; its late ACK is then not taken) or ``aborted`` (the bridge
stopped first: ``abort``, the reason says whether any of its frames went out). A NACKed
command's frames not sent yet are not sent. ``counters`` (in ``rates`` and the bridge's report):
commands waiting for the window (``commands_queued``), frames un-answered
(``command_frames_in_flight``), and the totals refused (queue full), expired in the queue, timed
out and aborted.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from odocan.host.mqtt import topics
from odocan.host.mqtt.livecommands import PendingAck
from odocan.host.mqtt.telemetry import Publication, RobotTelemetry
from odocan.host.protocol.commands import Command, CommandRejected, Frame

WINDOW_FRAMES = 8  # command frames (and their ODOM_AUTHs) un-answered on the bus per robot
ACK_TIMEOUT_S = 2.0  # the firmware answers within a tick: this long after the last frame
MAX_QUEUED = 1024  # commands waiting per robot; beyond, refused
# the telemetry's answers from the firmware's ODOM_ACK (``contested``: another tool's frames
# heard in its flight; ``unanswered``: its final frame ACKed, not all its staged ones;
# ``host.mqtt.livecommands``)
FINAL_ANSWERS = ("acked", "nacked", "contested", "unanswered")

# Puts one frame (and its ODOM_AUTH) on the bus: the mailbox slots it takes; CommandRejected
SendFrame = Callable[[Command, Frame], int]


@dataclass(eq=False)
class _Paced:
    """One command taken: its frames not sent yet, those in flight, and its deadline."""

    command: Command
    name: str
    queued_s: float
    next_frame: int = 0
    in_flight: dict[tuple[int, int], tuple[PendingAck, int]] = field(default_factory=dict)
    deadline_s: float | None = None  # set when its last frame went out

    @property
    def all_sent(self) -> bool:
        return self.next_frame >= len(self.command.frames)


class CommandPacer:
    """A robot's command frames, paced (see the module docstring)."""

    def __init__(
        self, telemetry: RobotTelemetry, send_frame: SendFrame, *,
        window_frames: int = WINDOW_FRAMES, ack_timeout_s: float = ACK_TIMEOUT_S,
        max_queued: int = MAX_QUEUED, expiry_s: float = 5.0,
    ) -> None:
        self._telemetry = telemetry
        self._send_frame = send_frame
        self.window_frames = max(1, min(window_frames, 15))  # distinct 4-bit COUNTERs
        self.ack_timeout_s = ack_timeout_s
        self.max_queued = max_queued
        self.expiry_s = expiry_s
        self._active: deque[_Paced] = deque()  # in bus order: sending, then awaiting the ACK
        self._frames_in_flight = 0
        self.refused = self.timed_out = self.expired = self.aborted = 0

    @property
    def busy(self) -> bool:
        """Commands still to send or to be answered."""
        return bool(self._active)

    @property
    def waiting(self) -> int:
        """Commands taken, none of their frames sent yet (``_active``'s tail: see ``_sent``)."""
        return len(self._active) - len(self._sent())

    def _sent(self) -> list[_Paced]:
        """The commands with frames on the bus, ``_active``'s head: a command's frames go out
        only once the one before it sent its last (``_send_more``), so the commands waiting
        (none sent) are the tail, in the order taken. Every step of ``pump`` looks at these
        few (the window is at most 15 frames) and the tail's head only: with 1 024 queued,
        walking them all for each frame heard took the bridge's loop."""
        sent = []
        for paced in self._active:
            if paced.next_frame == 0:
                break
            sent.append(paced)
        return sent

    def counters(self) -> dict[str, int]:
        """What the pacer holds now and what it answered itself (see the module docstring)."""
        return {"commands_queued": self.waiting,
                "command_frames_in_flight": self._frames_in_flight,
                "commands_refused": self.refused, "commands_queue_expired": self.expired,
                "commands_timeout": self.timed_out, "commands_aborted": self.aborted}

    def submit(self, command: Command, name: str, now_s: float) -> bool:
        """Take ``command`` (False: the queue is full, it is refused: not run); ``now_s`` may
        lie in the past: the command's life was partly spent before (``host.mqtt.expiry.Fresh``),
        and it expires ``expiry_s`` after it."""
        if self.waiting >= self.max_queued:
            self.refused += 1
            return False
        self._active.append(_Paced(command, name, now_s))
        return True

    def pump(self, now_s: float, published: list[Publication] = ()) -> list[Publication]:  # type: ignore[assignment]
        """The answers ``published`` (by the telemetry, just now) end their commands; frames
        answered free the window; overdue commands time out; then more frames go out. Returns
        the pacer's own final answers (timeout, expired, rejected)."""
        answers: list[Publication] = []
        self._release(published)
        self._expire(now_s, answers)
        self._send_more(now_s, answers)
        return answers

    def send_now(self, now_s: float) -> list[Publication]:
        """The frames the window takes now (a command just taken): only the answers of
        commands the bus refused; timeouts and expiries are ``pump``'s."""
        answers: list[Publication] = []
        self._send_more(now_s, answers)
        return answers

    def abort(self) -> list[Publication]:
        """The bridge stops: every command taken and not answered yet is answered
        ``aborted`` (in bus order), with whether it ran: none of its frames sent (not run),
        some but not its last (not run: the firmware only staged them), or all of them (its
        ODOM_ACK never heard: its outcome is unknown)."""
        answers: list[Publication] = []
        for paced in list(self._active):
            if paced.next_frame == 0:
                reason = "the bridge stopped before it was sent: not run"
            elif not paced.all_sent:
                reason = ("the bridge stopped before its last frame was sent: not run (the "
                          "firmware staged its first frames only)")
            else:
                reason = ("the bridge stopped before its ODOM_ACK was heard: its outcome is "
                          "unknown")
            self.aborted += 1
            self._finish(paced)
            answers.append(_answer(paced, "aborted", reason))
        return answers

    def _release(self, published: list[Publication]) -> None:
        """Free the slots of frames whose ODOM_ACK came (their PendingAck left the telemetry's
        ``pending``); a final answer published for a command ends it."""
        pending = self._telemetry.pending
        answered_ids = [p.get("id") for leaf, p in published
                        if leaf == topics.RESULT_LEAF and p.get("result") in FINAL_ANSWERS]
        for paced in self._sent():
            gone = [k for k, (ack, _) in paced.in_flight.items() if pending.get(k) is not ack]
            for key in gone:
                self._frames_in_flight -= paced.in_flight.pop(key)[1]
            if gone and paced.command.cmd_id in answered_ids:
                answered_ids.remove(paced.command.cmd_id)
                self._finish(paced)

    def _expire(self, now_s: float, answers: list[Publication]) -> None:
        sent = self._sent()
        for paced in sent:
            if paced.deadline_s is not None and now_s > paced.deadline_s:
                self.timed_out += 1
                self._finish(paced)
                answers.append(_answer(paced, "timeout", (
                    f"no ODOM_ACK from the firmware within {self.ack_timeout_s:g} s: "
                    "its outcome is unknown")))
        waiting = len(self._sent())  # the first waiting (taken in order: the oldest first)
        while len(self._active) > waiting:
            paced = self._active[waiting]
            if now_s - paced.queued_s <= self.expiry_s:
                break
            self.expired += 1
            self._finish(paced)
            answers.append(_answer(paced, "expired",
                                   "waited in the bridge's queue beyond its expiry: not run"))

    def _send_more(self, now_s: float, answers: list[Publication]) -> None:
        at = 0
        while at < len(self._active) and self._frames_in_flight < self.window_frames:
            paced = self._active[at]
            if paced.next_frame == 0 and now_s - paced.queued_s > self.expiry_s:
                self.expired += 1  # out of order: its life was shortened (``submit``)
                self._finish(paced)
                answers.append(_answer(paced, "expired",
                                       "waited in the bridge's queue beyond its expiry: not run"))
                continue
            at += 1
            while not paced.all_sent and self._frames_in_flight < self.window_frames:
                frame = paced.command.frames[paced.next_frame]
                try:
                    slots = self._send_frame(paced.command, frame)
                except CommandRejected as exc:
                    self._finish(paced)
                    answers.append(_answer(paced, "rejected", exc.reason))
                    at -= 1  # the next one took its place
                    break
                ack = self._telemetry.pending.get((frame.can_id, frame.counter))
                if ack is not None:
                    paced.in_flight[(frame.can_id, frame.counter)] = (ack, slots)
                    self._frames_in_flight += slots
                paced.next_frame += 1
                if paced.all_sent:
                    paced.deadline_s = now_s + self.ack_timeout_s
            if self._frames_in_flight >= self.window_frames:
                return

    def _finish(self, paced: _Paced) -> None:
        """``paced`` is answered: its frames not sent are dropped, and an ODOM_ACK still to
        come for it answers nothing (its PendingAcks leave the telemetry's ``pending``)."""
        pending = self._telemetry.pending
        for key, (ack, slots) in paced.in_flight.items():
            if pending.get(key) is ack:
                del pending[key]
            self._frames_in_flight -= slots
        paced.in_flight.clear()
        paced.next_frame = len(paced.command.frames)
        self._active.remove(paced)


def _answer(paced: _Paced, result: str, reason: str) -> Publication:
    payload: dict[str, Any] = {"id": paced.command.cmd_id, "command": paced.name,
                               "result": result, "reason": reason}
    return (topics.RESULT_LEAF, topics.stamp(payload))
