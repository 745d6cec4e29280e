"""Which expiry rule a command broke: the answer on ``cmd/result`` says it (#13).

``host.mqtt.link`` refuses a command as ``"expired"`` by one of three rules (its module
docstring): the MQTT v5 message expiry the broker passed on (what was left of the sender's
interval when it was delivered), or, without one, ``--command-expiry`` since it arrived here, or,
when it carries ``sent_unix_s``, ``--command-expiry`` since it was sent by this host's wall clock.
An answer that only said "older than its expiry" left its sender guessing which clock to fix:
``expired_by`` returns the verdict ``Expired``, still equal to ``"expired"`` (every handler that
compares the verdict goes on working), carrying in ``reason`` the rule and the ages it saw.
"""

from __future__ import annotations

import time

from odocan.host.mqtt.client import Arrived
from odocan.host.protocol.commands import command_sent_unix_s


class Expired(str):
    """The verdict ``"expired"`` with the reason for ``cmd/result`` (``reason``)."""

    reason: str

    def __new__(cls, reason: str) -> Expired:
        verdict = super().__new__(cls, "expired")
        verdict.reason = reason
        return verdict


def expired_by(message: Arrived, payload: bytes, command_expiry_s: float) -> Expired | None:
    """The rule ``message`` broke (see the module docstring), None when it is fresh by all.
    Ages in s: since it arrived (``time.monotonic``), since it was sent (``time.time``)."""
    waited_s = time.monotonic() - message.arrival_s
    if message.expiry_s is not None and waited_s > message.expiry_s:
        return Expired(f"expired by its MQTT v5 message expiry: the broker passed it on with "
                       f"{message.expiry_s:g} s left, and it waited {waited_s:.1f} s here: "
                       "not run")
    if message.expiry_s is None and waited_s > command_expiry_s:
        return Expired(f"expired on arrival age: it waited {waited_s:.1f} s here, more than "
                       f"the bridge's command expiry {command_expiry_s:g} s (it carried no "
                       "expiry of its own from the broker): not run")
    sent_unix_s = command_sent_unix_s(payload)
    if sent_unix_s is not None and time.time() - sent_unix_s > command_expiry_s:
        return Expired(f"expired by sent_unix_s: sent {time.time() - sent_unix_s:.1f} s ago by "
                       f"this host's clock, more than the bridge's command expiry "
                       f"{command_expiry_s:g} s: not run")
    return None


class Fresh(str):
    """The verdict ``"run"`` with what is left of the command's life (``remaining_s``, by the
    rules above): the pacer's queue (``host.mqtt.pacing``) counts its expiry from the command's
    submission, so a command that waited in the command reader's queue first must not wait
    there past what its rules left it."""

    remaining_s: float

    def __new__(cls, remaining_s: float) -> Fresh:
        verdict = super().__new__(cls, "run")
        verdict.remaining_s = remaining_s
        return verdict


def fresh(message: Arrived, payload: bytes, command_expiry_s: float) -> Fresh:
    """``message`` found fresh by ``expired_by``: the verdict with the least life its rules left."""
    waited_s = time.monotonic() - message.arrival_s
    left_s = (message.expiry_s if message.expiry_s is not None else command_expiry_s) - waited_s
    sent_unix_s = command_sent_unix_s(payload)
    if sent_unix_s is not None:
        left_s = min(left_s, command_expiry_s - max(0.0, time.time() - sent_unix_s))
    return Fresh(max(0.0, left_s))
