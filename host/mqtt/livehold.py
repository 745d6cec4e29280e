"""The bridge holds a robot's frames from an encoder frame a starved recorder's stamps cannot
decide, as the monitor does (``host.judge.livesettle``; issue #11, one judge: the monitor, the
bridge and ``analyze`` take the same frames).

The bridge calls each CAN ID's plan directly (``host.mqtt.liveplan``). While a hold waits, the
robot's plans are swapped in place for ones that only keep the frame (``hold``): the frames
that are not held pay nothing for it but one append to ``recent`` (a hold's context, the
frames judged before it). When the hold is due the plans come back, and the frames held are
fed to them again: those ``SettleHold`` judged, by plans whose E2E check gives the encoder
frames that verdict (``RobotTelemetry.forced_plans``, ``E2EMonitor.check_as``), the others by
the usual plans. Their publications come out at once, with the frame that ended the hold.
"""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING

import can

from odocan.host.judge.livegapseen import heard_encoder
from odocan.host.judge.livesettle import CONTEXT_FRAMES, SettleHold
from odocan.host.mqtt.liveplan import Plan, Publication
from odocan.host.protocol.busfacts import ENC_MESSAGE

if TYPE_CHECKING:
    from odocan.host.mqtt.telemetry import RobotTelemetry

Recent = tuple[float, int, bytes, bool]  # bus time s, 11-bit id, payload, taken


def _message(t_s: float, can_id: int, data: bytes) -> can.Message:
    return can.Message(timestamp=t_s, arbitration_id=can_id, is_extended_id=False, data=data)


class BridgeHold:
    """One robot's hold in the bridge (module docstring)."""

    def __init__(self, telemetry: RobotTelemetry) -> None:
        self._telemetry = telemetry
        self.settle = SettleHold(telemetry.e2e, telemetry.db)
        self.recent: deque[Recent] = deque(maxlen=CONTEXT_FRAMES)  # the frames judged
        self._plans: dict[int, Plan] | None = None  # the usual plans while swapped out
        self.verdict: bool | None = None  # the verdict the forced plans' check gives

    def open(self, can_id: int, data: bytes, t_s: float) -> list[Publication]:
        """The encoder frame (``can_id``, ``data``, bus time ``t_s``) was held: hold from it."""
        self._context()
        self.settle.open(_message(t_s, can_id, data), t_s)
        self._swap()
        return []

    def hold(self, t_s: float, can_id: int, data: bytes) -> list[Publication]:
        """A frame heard while a hold waits: kept; the hold judged once it is due."""
        self.settle.held.append((_message(t_s, can_id, data), t_s))
        return self.release() if self.settle.due(t_s) else []

    def release(self, ends: bool = False) -> list[Publication]:
        """The plans back, the frames held judged and fed again (``SettleHold.release``; all
        with their verdicts when the watch ``ends``); their publications."""
        telemetry = self._telemetry
        if self._plans is not None:
            telemetry.plans.update(self._plans)
            self._plans = None
        self._context()
        published: list[Publication] = []
        forced = telemetry.forced_plans(self)
        encoders = telemetry.db.get_message_by_name(ENC_MESSAGE)

        def feed(msg: can.Message, now_s: float, verdict: bool | None) -> None:
            t_s, can_id, data = msg.timestamp, msg.arbitration_id, bytes(msg.data)
            self.verdict = verdict
            if verdict is not None and self.settle.unheard(msg, verdict):  # (the usual plans
                heard_encoder(telemetry.tracker, encoders, data)  # hear it: liveplan)
            plan = (telemetry.plans if verdict is None else forced).get(can_id)
            published.extend(plan(t_s, data) if plan is not None
                             else telemetry.feed_fields(t_s, can_id, data, False))

        def again(msg: can.Message, now_s: float) -> None:
            published.extend(telemetry.feed_fields(msg.timestamp, msg.arbitration_id,
                                                   bytes(msg.data), False))

        self.settle.release(feed, None if ends else again)
        if self.settle.held and self._plans is None:
            self._swap()  # held on (a starved recorder still)
        return published

    def _context(self) -> None:
        """The frames judged before the hold, as ``SettleHold`` reads them."""
        self.settle.recent.clear()
        self.settle.recent.extend((_message(t_s, can_id, data), taken)
                                  for t_s, can_id, data, taken in self.recent)

    def _swap(self) -> None:
        """Every plan keeps its frame instead (``hold``) until the hold is judged."""
        plans = self._telemetry.plans
        self._plans = dict(plans)
        for can_id in plans:
            plans[can_id] = self._keeper(can_id)

    def _keeper(self, can_id: int) -> Plan:
        hold = self.hold

        def keep(t_s: float, data: bytes) -> list[Publication]:
            return hold(t_s, can_id, data)

        return keep
