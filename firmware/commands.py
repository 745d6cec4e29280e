"""Step 3 for the host's commands: ODOM_SET_POSE, ODOM_CONFIG and NAV_GOAL, each answered.

ODOM_SET_POSE and ODOM_CONFIG are staged writes: each field frame is stored (ACK), APPLY commits
the current values overwritten by the staged ones, all or nothing (ODOM_CONFIG APPLY validates
the whole set first: NACK OUT_OF_RANGE or INCONSISTENT, nothing changed). NAV_GOAL goes to the
navigator (``firmware.nav``), which gives the ACK's reason. A frame whose multiplexer this
firmware does not know is NACKed UNKNOWN_FIELD. With SecOC, a frame that passed its E2E check
is first held for its ODOM_AUTH (``firmware.auth``) and acted on only once that verifies.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from odocan.firmware import frames as fr
from odocan.firmware.config import (
    ConfigReason,
    RobotParams,
    derive_constants,
    profile_crc32,
    validate_at_speed,
)
from odocan.firmware.e2e import E2EReceiver, E2EStatus
from odocan.firmware.errors import ErrorFlag, State
from odocan.firmware.fixmath import U64_MAX
from odocan.firmware.nav import q40_from_100um
from odocan.firmware.reception import FRAME_BYTES
from odocan.firmware.secoc import AuthRequest

if TYPE_CHECKING:
    from odocan.firmware.ecu import OdomEcu

CommandFrame = fr.OdomSetPose | fr.OdomConfig | fr.NavGoal

_CONFIG_FIELDS = {
    fr.ConfigParam.COUNTS_PER_REV: "counts_per_rev",
    fr.ConfigParam.WHEEL_RADIUS_LEFT: "wheel_radius_left_nm",
    fr.ConfigParam.WHEEL_RADIUS_RIGHT: "wheel_radius_right_nm",
    fr.ConfigParam.WHEELBASE: "wheelbase_nm",
    fr.ConfigParam.COUNTER_BITS: "counter_bits",
    fr.ConfigParam.INTEGRATOR: "integrator",
    fr.ConfigParam.MAX_WHEEL_SPEED: "max_wheel_speed_mm_s",
}


class Commands:
    """The command receivers and their staging (C: three E2E receivers and two staging sets)."""

    def __init__(self, ecu: OdomEcu) -> None:
        self._ecu = ecu
        self.rx_set_pose = E2EReceiver(fr.ODOM_SET_POSE_DATA_IDS, max_delta_counter_init=15)
        self.rx_config = E2EReceiver(fr.ODOM_CONFIG_DATA_IDS, max_delta_counter_init=15)
        self.rx_nav_goal = E2EReceiver(fr.NAV_GOAL_DATA_IDS, max_delta_counter_init=15)
        self._staged_pose: dict[int, int] = {}
        self._staged_config: dict[int, int] = {}
        self._config_taken = bytes(FRAME_BYTES)  # the last ODOM_CONFIG frame accepted (u8[8])

    # --- received frames: E2E, then held for SecOC or acted on ---

    def on_set_pose(self, data: bytes) -> None:
        """One ODOM_SET_POSE frame from the mailbox."""
        ecu = self._ecu
        if ecu.reception.usable(self.rx_set_pose, data) and not ecu.auth.held_for_auth(
            AuthRequest.ODOM_SET_POSE, data
        ):
            self.act_set_pose(data)

    def on_config(self, data: bytes) -> None:
        """One ODOM_CONFIG frame from the mailbox. A frame the E2E check refuses as REPEATED
        with other content than the last one accepted (two senders on ODOM_CONFIG, each with
        its own COUNTER, or one that restarted its COUNTER) is NACKed REPEATED: dropped,
        nothing staged, but its sender is told; a duplicate of the accepted one (CAN's double
        reception) stays unanswered: it was answered once."""
        ecu = self._ecu
        if ecu.reception.usable(self.rx_config, data):
            self._config_taken = data  # C: memcpy of the 8 bytes
            if not ecu.auth.held_for_auth(AuthRequest.ODOM_CONFIG, data):
                self.act_config(data)
        elif len(data) == FRAME_BYTES and self.rx_config.status is E2EStatus.REPEATED \
                and data != self._config_taken:
            frame = fr.unpack_odom_config(data)
            self.ack(fr.ODOM_CONFIG_ID, frame, fr.AckResult.NACK, fr.AckReason.REPEATED)

    def on_nav_goal(self, data: bytes) -> None:
        """One NAV_GOAL frame from the mailbox."""
        ecu = self._ecu
        if ecu.reception.usable(self.rx_nav_goal, data) and not ecu.auth.held_for_auth(
            AuthRequest.NAV_GOAL, data
        ):
            self.act_nav_goal(data)

    # --- acting on a frame (E2E OK, and authenticated when SecOC is on) ---

    def act_set_pose(self, data: bytes) -> None:
        """Stage X, Y or HEADING, or APPLY the staged pose; ACK, or NACK UNKNOWN_FIELD."""
        frame = fr.unpack_odom_set_pose(data)
        field = frame.field
        if field == fr.SetPoseField.APPLY:
            x_q40, y_q40, heading = self._pose_with(self._staged_pose)
            self._ecu.odometry.set_pose(x_q40, y_q40, heading)
            self._staged_pose.clear()
            self._ecu.health.pose_set()  # a pose given again: COUNTER_RESET may recover
            self._ecu.uncertainty.pose_set()  # and the uncertainty restarts
        elif field in (fr.SetPoseField.X, fr.SetPoseField.Y, fr.SetPoseField.HEADING):
            self._staged_pose[field] = frame.value
        else:
            self.ack(fr.ODOM_SET_POSE_ID, frame, fr.AckResult.NACK, fr.AckReason.UNKNOWN_FIELD)
            return
        self.ack(fr.ODOM_SET_POSE_ID, frame, fr.AckResult.ACK, fr.AckReason.OK)

    def _pose_with(self, staged: dict[int, int]) -> tuple[int, int, int]:
        """The current pose overwritten by the staged fields (X/Y in 0.1 mm, heading in BAM16)."""
        odo = self._ecu.odometry
        x_q40 = odo.x_q40_m
        y_q40 = odo.y_q40_m
        heading = odo.heading_bam64
        if fr.SetPoseField.X in staged:
            x_q40 = q40_from_100um(staged[fr.SetPoseField.X])
        if fr.SetPoseField.Y in staged:
            y_q40 = q40_from_100um(staged[fr.SetPoseField.Y])
        if fr.SetPoseField.HEADING in staged:
            heading = (staged[fr.SetPoseField.HEADING] << 48) & U64_MAX
        return x_q40, y_q40, heading

    def act_config(self, data: bytes) -> None:
        """Stage one parameter (ACK), APPLY the staged set, or NACK UNKNOWN_FIELD."""
        frame = fr.unpack_odom_config(data)
        if frame.param == fr.ConfigParam.APPLY:
            self._apply_config(frame)
        elif frame.param in _CONFIG_FIELDS:
            self._staged_config[frame.param] = frame.value
            self.ack(fr.ODOM_CONFIG_ID, frame, fr.AckResult.ACK, fr.AckReason.OK)
        else:
            self.ack(fr.ODOM_CONFIG_ID, frame, fr.AckResult.NACK, fr.AckReason.UNKNOWN_FIELD)

    def _apply_config(self, frame: fr.OdomConfig) -> None:
        """Validate the current parameters overwritten by the staged ones; commit all or nothing."""
        ecu = self._ecu
        values = {name: getattr(ecu.params, name) for name in _CONFIG_FIELDS.values()}
        for param, value in self._staged_config.items():
            values[_CONFIG_FIELDS[fr.ConfigParam(param)]] = value
        self._staged_config.clear()
        candidate = RobotParams(**values)
        reason = validate_at_speed(candidate, candidate.max_wheel_speed_mm_s)
        if reason is not ConfigReason.OK:
            ecu.errors.set(ErrorFlag.CONFIG_INVALID)
            ack_reason = (
                fr.AckReason.INCONSISTENT
                if reason in (ConfigReason.GEOMETRY_ABSURD, ConfigReason.WIRE_RANGE)
                else fr.AckReason.OUT_OF_RANGE
            )
            self.ack(fr.ODOM_CONFIG_ID, frame, fr.AckResult.NACK, ack_reason)
            return
        bits_changed = candidate.counter_bits != ecu.params.counter_bits
        if bits_changed:
            ecu.odometry.unprime()
        ecu.params = candidate
        ecu.uncertainty.params = candidate
        ecu.profile_crc = profile_crc32(candidate)
        ecu.odometry.reconfigure(derive_constants(candidate, ecu.errors))
        ecu.encoders.max_wheel_speed_mm_s = candidate.max_wheel_speed_mm_s
        ecu.encoders.reconfigure(bits_changed)
        ecu.health.config_applied()
        self.ack(fr.ODOM_CONFIG_ID, frame, fr.AckResult.ACK, fr.AckReason.OK)

    def act_nav_goal(self, data: bytes) -> None:
        """Hand the NAV_GOAL frame to the navigator; ACK, or NACK with its reason."""
        frame = fr.unpack_nav_goal(data)
        ecu = self._ecu
        reason = ecu.nav.request(frame, ecu.health.state is State.OK)
        result = fr.AckResult.ACK if reason is fr.AckReason.OK else fr.AckResult.NACK
        self.ack(fr.NAV_GOAL_ID, frame, result, reason)

    def ack(
        self,
        request_id: int,
        frame: CommandFrame,
        result: fr.AckResult,
        reason: fr.AckReason,
    ) -> None:
        """ODOM_ACK answering ``frame`` (its COUNTER and multiplexer value) of ``request_id``."""
        tx = self._ecu.tx
        data = fr.pack_odom_ack(
            tx.next_counter(fr.ODOM_ACK_ID),
            frame.counter,
            request_id,
            frame.param if isinstance(frame, fr.OdomConfig) else frame.field,
            result,
            reason,
            self._ecu.errors,
        )
        tx.send(fr.ODOM_ACK_ID, data)

