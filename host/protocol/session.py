"""A host's command session with one firmware: commands out, ODOM_ACK and NAV_STATUS in.

Every host that drives a firmware over CAN (the experiments' ``NavSession``, the pytest kit's
``OdocanRig``) does the same three things, here once:

* **send** a command (set_pose, config, nav_goal: ``host.protocol.commands``), validated against
  the DBC and built into E2E-protected frames from Python values (``CommandEncoder.build``), each
  secured frame followed by its ODOM_AUTH when the session has a SecOC signer
  (``host.protocol.secoc``; its freshness first learnt from ODOM_FRESHNESS);
* **wait for its ODOM_ACK**: the answer to the committing frame (REQUEST_ID its message,
  REQUEST_COUNTER its E2E COUNTER); any NACK among the answers since it was sent, or none within
  ``ack_timeout_s``, is a ``CommandNotAcked`` naming the reason, and so is an ACK while
  another sender's frames of the same message were heard (``host.protocol.othersenders``:
  the ACK may be the other's);
* **follow NAV_STATUS**: the states a goal went through since its ACK (``goal_states``), whether
  it ended (REACHED, STOPPED, ABORTED), and every change of (GOAL_ID, STATE) as it is heard
  (``status_changes``).

What the firmware says is read from a ``host.protocol.heard.Recorder`` (E2E-checked, decoded by
cantools, choices by name); time passes through the caller's ``wait(done, timeout_s)`` (a lockstep
rig steps simulated time, a real bus sleeps), so the session works the same in both.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Final

from odocan.host.protocol import busfacts
from odocan.host.protocol.commands import Command, CommandEncoder
from odocan.host.protocol.e2e import REPEATED, e2e_messages
from odocan.host.protocol.heard import Recorder
from odocan.host.protocol.othersenders import contested_reason, foreign_frame
from odocan.host.protocol.secoc import SecocSigner
from odocan.sim.exceptions import OdocanError

Send = Callable[[int, bytes], None]  # send a frame as the HOST: CAN ID, data
Wait = Callable[[Callable[[], bool], float], bool]  # let time pass until done() or timeout_s
ENDED: Final = frozenset({"REACHED", "STOPPED", "ABORTED"})  # NAV_STATUS states that end a goal
OWN_FRAMES: Final = 64  # the frames a session remembers sending (told from another sender's)
# the firmware sends ODOM_FRESHNESS every GenMsgCycleTime (1 s): half a cycle more
FRESHNESS_WAIT_S: Final = 1.5 * busfacts.FRESHNESS_CYCLE_MS / busfacts.MS_PER_S


class CommandNotAcked(OdocanError):
    """The firmware answered a command with ODOM_ACK NACK, or not at all: the command's name,
    its ``values`` and the ``reason``, ``"NACK <REASON>"`` or ``"no ODOM_ACK"``."""

    def __init__(self, command: str, values: Mapping[str, Any], reason: str) -> None:
        super().__init__(f"{command} {dict(values)}: {reason} from the firmware")
        self.command = command
        self.values = dict(values)
        self.reason = reason


class SecocUnsynchronised(OdocanError):
    """No usable ODOM_FRESHNESS: the session cannot sign a command."""


@dataclass(frozen=True)
class StatusChange:
    """NAV_STATUS showed ``state`` for ``goal_id`` (``queue_depth`` goals still queued) for the
    first time since the previous change, at ``timestamp_s``."""

    goal_id: int
    state: str
    queue_depth: int
    timestamp_s: float


class CommandSession:
    """Commands to one firmware and what it answers (module docstring).

    Args:
        heard: what the host hears on the bus.
        send: sends one frame as the HOST.
        wait: lets time pass until ``done()`` (True) or ``timeout_s`` (False).
        ack_timeout_s: how long an ODOM_ACK may take (s, of the ``wait`` clock).
        encoder: the HOST's command encoder (it owns the E2E counters: one per robot).
        signer: the SecOC signer (None: commands are not signed).
    """

    def __init__(
        self,
        heard: Recorder,
        send: Send,
        wait: Wait,
        *,
        ack_timeout_s: float,
        encoder: CommandEncoder | None = None,
        signer: SecocSigner | None = None,
    ) -> None:
        self.heard = heard
        self.send = send
        self.wait = wait
        self.ack_timeout_s = ack_timeout_s
        self.encoder = encoder if encoder is not None else CommandEncoder()
        self.signer = signer
        self.goal_acked_at: dict[int, float] = {}  # goal id -> its ACK's timestamp_s
        self._status_seen = 0  # NAV_STATUS frames taken by status_changes
        self._previous: tuple[int, str] | None = None
        self._own: deque[bytes] = deque(maxlen=OWN_FRAMES)  # the latest frames it sent

    # --- commands ---------------------------------------------------------------------------

    def command(self, name: str, values: Mapping[str, Any]) -> dict[str, Any]:
        """Send command ``name`` and wait for the ODOM_ACK of its committing frame; returns that
        ACK (decoded, with ``timestamp_s``). ``CommandRejected`` (nothing sent) when it is not
        valid; ``CommandNotAcked`` on a NACK or no answer in ``ack_timeout_s``."""
        cmd = self.encoder.build(name, values)
        signer = self._synchronised_signer()
        seen = len(self.heard.decoded("ODOM_ACK"))
        refused = sum(self.heard.refused("ODOM_ACK").values())
        first = len(self.heard)  # frames heard before this command's
        for frame in cmd.frames:
            self._own.append(frame.data)
            self.send(frame.can_id, frame.data)
            if signer is not None and signer.is_secured(frame.can_id):
                self.send(signer.auth_frame_id, signer.sign(frame.can_id, frame.data))
        self.wait(lambda: self._answer(cmd, seen) is not None, self.ack_timeout_s)
        nacks = [a for a in self.heard.decoded("ODOM_ACK", seen) if a["RESULT"] == "NACK"]
        final = self._answer(cmd, seen)
        if signer is not None and any(str(a["REASON"]).startswith("AUTH_") for a in nacks):
            signer.next_fv = None  # resynchronise from the next ODOM_FRESHNESS
        self._uncontested(cmd, first)  # another sender: any answer may be the other's
        if nacks or final is None:
            why = f"NACK {nacks[0]['REASON']}" if nacks else self._unanswered(refused)
            raise CommandNotAcked(name, values, why)
        return final

    def _unanswered(self, refused_before: int) -> str:
        """Why no ACK answered: none heard, or those heard since (``refused_before`` were
        refused before the command) all failed their E2E check, by status (REPEATED: the
        firmware's E2E COUNTER does not advance; an outside trial's firmware read as silent)."""
        refused = self.heard.refused("ODOM_ACK")
        if sum(refused.values()) <= refused_before:
            return "no ODOM_ACK"
        counts = ", ".join(f"{n} {status}" for status, n in sorted(refused.items()))
        stuck = (": the firmware's E2E COUNTER does not advance" if REPEATED in refused else "")
        return f"no ODOM_ACK that passed its E2E check ({counts} refused{stuck})"

    def _uncontested(self, cmd: Command, first: int) -> None:
        """``CommandNotAcked`` (contested) when another sender's frame of ``cmd``'s message
        was heard since frame ``first`` (``host.protocol.othersenders``): its ACK proves
        nothing. A frame this session sent (an earlier command's, heard late) is its own."""
        can_id = cmd.frames[0].can_id
        message = next((m for m in e2e_messages(self.heard.db).values() if m.key == can_id),
                       None)
        if message is None:
            return
        data = foreign_frame(self.heard.arrays(), first, message, self._own)
        if data is not None:
            raise CommandNotAcked(cmd.name, cmd.values, contested_reason(message.name, data))

    def set_pose(self, x_m: float, y_m: float, heading_rad: float) -> dict[str, Any]:
        """Overwrite the on-board pose (ODOM_SET_POSE); the ACK."""
        return self.command("set_pose", {"x_m": x_m, "y_m": y_m, "heading_rad": heading_rad})

    def configure(
        self,
        *,
        counts_per_rev: int,
        wheel_radius_left_m: float,
        wheel_radius_right_m: float,
        wheelbase_m: float,
        counter_bits: int,
        integrator: str,
        max_wheel_speed_m_s: float | None = None,
    ) -> dict[str, Any]:
        """Write the robot's parameters (ODOM_CONFIG staged writes, then APPLY); the ACK.
        ``max_wheel_speed_m_s`` None: the firmware keeps the bound it has."""
        values: dict[str, Any] = {
            "counts_per_rev": counts_per_rev,
            "wheel_radius_left_m": wheel_radius_left_m,
            "wheel_radius_right_m": wheel_radius_right_m,
            "wheelbase_m": wheelbase_m,
            "counter_bits": counter_bits,
            "integrator": integrator,
        }
        if max_wheel_speed_m_s is not None:
            values["max_wheel_speed_m_s"] = max_wheel_speed_m_s
        return self.command("config", values)

    def goal(
        self,
        x_m: float,
        y_m: float,
        heading_rad: float | None = None,
        *,
        goal_id: int,
        mode: str = "turn_go_turn",
        append: bool = False,
    ) -> dict[str, Any]:
        """Send a NAV_GOAL (REPLACE the path, or ``append`` to it; no final heading when
        ``heading_rad`` is None); the ACK, whose time starts the goal's ``goal_states``."""
        values: dict[str, Any] = {
            "x_m": x_m, "y_m": y_m, "mode": mode, "append": append, "goal_id": goal_id,
        }
        if heading_rad is not None:
            values["heading_rad"] = heading_rad
        ack = self.command("nav_goal", values)
        self.goal_acked_at[goal_id] = float(ack["timestamp_s"])
        return ack

    def _answer(self, cmd: Command, seen: int) -> dict[str, Any] | None:
        """The ODOM_ACK of ``cmd``'s last frame among the ACKs after the first ``seen``."""
        last = cmd.frames[-1]
        name = self.heard.db.get_message_by_frame_id(last.can_id).name
        for ack in self.heard.decoded("ODOM_ACK", seen):
            if ack["REQUEST_COUNTER"] == last.counter and str(ack["REQUEST_ID"]) == name:
                return ack
        return None

    def _synchronised_signer(self) -> SecocSigner | None:
        """The SecOC signer (None: no key), its freshness from the firmware's ODOM_FRESHNESS
        (waited for, at most ``FRESHNESS_WAIT_S``: the firmware sends one every second)."""
        signer = self.signer
        if signer is None or signer.next_fv is not None:
            return signer
        seen = len(self.heard.decoded("ODOM_FRESHNESS"))
        self.wait(lambda: len(self.heard.decoded("ODOM_FRESHNESS")) > seen, FRESHNESS_WAIT_S)
        frames = self.heard.decoded("ODOM_FRESHNESS")
        latest = frames[-1] if frames else None
        if latest is None or not signer.adopt(int(latest["FV_EPOCH"]), int(latest["FV_COUNT"])):
            raise SecocUnsynchronised(
                f"SecOC: no usable ODOM_FRESHNESS from the firmware ({latest})"
            )
        return signer

    # --- navigation ---------------------------------------------------------------------------

    def goal_states(self, goal_id: int) -> list[dict[str, Any]]:
        """The NAV_STATUS frames of ``goal_id`` heard since its ACK (all of them when it was
        not sent by this session)."""
        since = self.goal_acked_at.get(goal_id, -math.inf)
        return [f for f in self.heard.decoded("NAV_STATUS")
                if f["GOAL_ID"] == goal_id and f["timestamp_s"] >= since]

    def goal_ended(self, goal_id: int) -> bool:
        """NAV_STATUS showed ``goal_id`` REACHED, STOPPED or ABORTED since its ACK."""
        return any(f["STATE"] in ENDED for f in self.goal_states(goal_id))

    def status_changes(self) -> list[StatusChange]:
        """The NAV_STATUS (GOAL_ID, STATE) changes heard since the previous call, in order."""
        frames = self.heard.decoded("NAV_STATUS", self._status_seen)
        self._status_seen += len(frames)
        changes = []
        for f in frames:
            now = (int(f["GOAL_ID"]), str(f["STATE"]))
            if now != self._previous:
                self._previous = now
                changes.append(StatusChange(*now, int(f["QUEUE_DEPTH"]), float(f["timestamp_s"])))
        return changes
