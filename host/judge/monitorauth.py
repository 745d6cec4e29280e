"""SecOC as the monitor follows it (``odocan monitor``; docs/secoc.md): the secured command
frames awaiting their ODOM_AUTH, and the firmware's AUTH_* refusals counted. Moved out of
``host.judge.monitor`` at its 500 lines (``BusMonitor.auth`` is ``AuthWatch.counts``)."""

from __future__ import annotations

from collections import Counter
from typing import Any

# SecOC counts shown by the monitor: ODOM_ACK NACK reasons AUTH_*, and ODOM_AUTH frames that
# follow no secured command frame (a forger's, or a command lost on the way).
AUTH_COUNTS = ("auth_failed", "auth_freshness", "auth_missing", "auth_unavailable",
               "auth_without_command")


class AuthWatch:
    """The secured messages with a command frame awaiting ODOM_AUTH, and the counts."""

    def __init__(self) -> None:
        self.counts: Counter[str] = Counter({name: 0 for name in AUTH_COUNTS})
        self._awaiting: set[str] = set()  # secured messages with a command frame heard last

    def command(self, request: str) -> None:
        """A command frame of the secured message ``request``: its ODOM_AUTH may follow."""
        self._awaiting.add(request)

    def authenticates(self, request: str) -> bool:
        """ODOM_AUTH naming ``request``: whether it authenticates a command frame awaiting it
        (as the firmware's held slot does); one that follows none is counted."""
        if request in self._awaiting:
            self._awaiting.discard(request)
            return True
        self.counts["auth_without_command"] += 1
        return False

    def refusal(self, shown: dict[str, Any], t_s: float) -> dict[str, Any] | None:
        """An ODOM_ACK's ``shown`` values: a NACK with an AUTH_* reason is counted, and its
        event (bus time ``t_s``) given; else None."""
        reason = str(shown.get("REASON", ""))
        if not reason.startswith("AUTH_"):
            return None
        self.counts[reason.lower()] += 1
        request = shown.get("REQUEST_ID", "?")
        return {"t_s": t_s, "kind": "auth", "detail": f"{request} refused: {reason}"}
