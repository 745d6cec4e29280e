"""SecOC on the ECU: verify before acting (docs/secoc.md; the verifier is ``firmware.secoc``).

A firmware provisioned with a key (``secoc_key``, configuration from the board, never on the bus)
holds each ODOM_SET_POSE, ODOM_CONFIG and NAV_GOAL frame that passed its E2E check and acts on it
only when the ODOM_AUTH that follows verifies; otherwise it answers ODOM_ACK NACK with the AUTH
reason (AUTH_FAILED, AUTH_FRESHNESS, AUTH_MISSING after ``AUTH_TIMEOUT_TICKS`` or when displaced,
AUTH_UNAVAILABLE). It sends ODOM_FRESHNESS at boot, every second and after a refusal. EPOCH
lives in the board's ``FreshnessNvm`` cell. Without a key the firmware behaves as before SecOC
(ODOM_AUTH is filtered, nothing extra is sent).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from odocan.firmware import frames as fr
from odocan.firmware.e2e import E2EReceiver
from odocan.firmware.hal import FreshnessNvm
from odocan.firmware.secoc import (
    FRESHNESS_PERIOD_TICKS,
    AuthRequest,
    AuthStatus,
    FreshnessCause,
    Held,
    SecocReceiver,
    SecuredCommands,
)

if TYPE_CHECKING:
    from odocan.firmware.ecu import OdomEcu


class Auth:
    """The ECU's SecOC glue: ODOM_AUTH's receiver and the held commands (None: no key)."""

    def __init__(self, ecu: OdomEcu, key: bytes | None, nvm: FreshnessNvm | None) -> None:
        """``key`` (16 bytes; None: no SecOC) and ``nvm`` (the EPOCH cell; None with a key:
        secured commands unavailable). Boot: EPOCH + 1 is written to the NVM first."""
        self._ecu = ecu
        self.rx_auth = E2EReceiver(fr.ODOM_AUTH_DATA_IDS, max_delta_counter_init=15)
        self.secoc: SecuredCommands | None = None
        if key is not None:
            self.secoc = SecuredCommands(SecocReceiver(key, nvm or _NoNvm()))

    def held_for_auth(self, request: AuthRequest, data: bytes) -> bool:
        """True when the frame (E2E OK) was held for its ODOM_AUTH instead of acted on now; a
        frame it displaced is refused (NACK AUTH_MISSING)."""
        if self.secoc is None:
            return False
        displaced = self.secoc.hold(request, data, self._ecu.clock.ticks)
        if displaced is not None:
            self._nack_held(displaced, AuthStatus.MISSING)
        return True

    def on_auth(self, data: bytes) -> None:
        """ODOM_AUTH: verify the held frame it names; act on it, or NACK it with the verdict."""
        ecu = self._ecu
        if self.secoc is None or not ecu.reception.usable(self.rx_auth, data):
            return
        result = self.secoc.authenticate(fr.unpack_odom_auth(data))
        if result is None:  # nothing held for it: counted (orphans), no answer
            return
        status, held = result
        commands = ecu.commands
        if status is not AuthStatus.OK:
            self._nack_held(held, status)
        elif held.can_id == fr.ODOM_SET_POSE_ID:
            commands.act_set_pose(held.pdu)
        elif held.can_id == fr.ODOM_CONFIG_ID:
            commands.act_config(held.pdu)
        else:
            commands.act_nav_goal(held.pdu)

    def expire_held(self) -> None:
        """Held frames whose ODOM_AUTH did not come in time: NACK AUTH_MISSING."""
        if self.secoc is None:
            return
        ticks = self._ecu.clock.ticks
        held = self.secoc.expire(ticks)
        while held is not None:
            self._nack_held(held, AuthStatus.MISSING)
            held = self.secoc.expire(ticks)

    def _nack_held(self, held: Held, status: AuthStatus) -> None:
        """ODOM_ACK NACK for a held secured frame, REASON the AUTH verdict (7..10)."""
        frame: fr.OdomSetPose | fr.OdomConfig | fr.NavGoal
        if held.can_id == fr.ODOM_SET_POSE_ID:
            frame = fr.unpack_odom_set_pose(held.pdu)
        elif held.can_id == fr.ODOM_CONFIG_ID:
            frame = fr.unpack_odom_config(held.pdu)
        else:
            frame = fr.unpack_nav_goal(held.pdu)
        self._ecu.commands.ack(held.can_id, frame, fr.AckResult.NACK, fr.AckReason(int(status)))

    def send_freshness(self) -> None:
        """ODOM_FRESHNESS when due (boot, refusal, rollover, unavailable) and every second."""
        if self.secoc is None:
            return
        receiver = self.secoc.receiver
        cause = receiver.take_sync_cause()
        if cause is None and self._ecu.clock.ticks % FRESHNESS_PERIOD_TICKS == 0:
            cause = FreshnessCause.PERIODIC
        if cause is not None:
            tx = self._ecu.tx
            counter = tx.next_counter(fr.ODOM_FRESHNESS_ID)
            tx.send(fr.ODOM_FRESHNESS_ID, receiver.freshness_frame(counter, cause))


class _NoNvm:
    """No NVM cell given: every write fails, so secured commands are unavailable (fail closed)."""

    def read_epoch(self) -> int:
        return 0

    def write_epoch(self, epoch: int) -> bool:
        return False
