"""Step 5 of the tick: the scheduled transmissions, at the DBC's cycle times.

ODOM_POSE_X/Y and ODOM_TWIST every 20 ms (once out of INIT), ODOM_STATUS every 100 ms (the
summary page, then one rotating page of counts or the running profile), MOTOR_CMD every 20 ms
while navigating, NAV_STATUS every 100 ms and in the tick its STATE or GOAL_ID changes,
ODOM_FRESHNESS when SecOC has one due (``firmware.auth``).
Each reads the ECU's state; none changes it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from odocan.firmware import frames as fr
from odocan.firmware.e2e import E2EReceiver
from odocan.firmware.errors import State
from odocan.firmware.fixmath import (
    U16_MAX,
    div_round_i64,
    mul_shr_round_i64,
    wrap_i16,
    wrap_i32,
    wrap_u32,
)

if TYPE_CHECKING:
    from odocan.firmware.ecu import OdomEcu

POSE_PERIOD_TICKS = 2  # ODOM_POSE_X/Y, ODOM_TWIST: 20 ms
STATUS_PERIOD_TICKS = 10  # ODOM_STATUS: 100 ms
_INIT = State.INIT  # the enumerator as a module constant (a 3.11 enum attribute read: ~0.14 us)
_ROTATING_PAGES = (
    fr.StatusPage.FRAME_TOTALS,
    fr.StatusPage.E2E_WHEEL_ENCODERS,
    fr.StatusPage.E2E_ODOM_SET_POSE,
    fr.StatusPage.E2E_ODOM_CONFIG,
    fr.StatusPage.E2E_NAV_GOAL,
    fr.StatusPage.PROFILE,
)


class Reports:
    """What the ECU sends on schedule (C: the rotating page's u8 index)."""

    def __init__(self, ecu: OdomEcu) -> None:
        self._ecu = ecu
        self._page_index = 0

    def transmit_scheduled(self, motor_cmd_due: bool) -> None:
        """Every frame due in this tick (``motor_cmd_due``: the navigator's step asked for one)."""
        ecu = self._ecu
        ticks = ecu.clock.ticks
        if motor_cmd_due:
            nav = ecu.nav
            cmd = fr.pack_motor_cmd(
                ecu.tx.next_counter(fr.MOTOR_CMD_ID), nav.left_mm_s, nav.right_mm_s, ecu.errors
            )
            ecu.tx.send(fr.MOTOR_CMD_ID, cmd)
        if ticks % POSE_PERIOD_TICKS == 0 and ecu.health.state is not _INIT:
            self._send_pose_and_twist()
        status_due = ticks % STATUS_PERIOD_TICKS == 0
        if status_due:
            self._send_status()
        if status_due or ecu.nav.changed:
            self._send_nav_status()
        auth = ecu.auth
        if auth.secoc is not None:  # C: compiled in with SecOC
            auth.send_freshness()

    def _send_nav_status(self) -> None:
        """NAV_STATUS; DISTANCE is clamped to its 65.535 m range here (a display limit)."""
        ecu = self._ecu
        nav = ecu.nav
        nav.changed = False
        distance_mm = min(div_round_i64(nav.distance_um, 1000), U16_MAX)
        heading_error_bam16 = wrap_i16((nav.heading_error_bam32 + (1 << 15)) >> 16)
        data = fr.pack_nav_status(
            ecu.tx.next_counter(fr.NAV_STATUS_ID),
            nav.state,
            nav.goal_id,
            nav.depth,
            distance_mm,
            heading_error_bam16,
            ecu.errors,
        )
        ecu.tx.send(fr.NAV_STATUS_ID, data)

    def _send_pose_and_twist(self) -> None:
        """ODOM_POSE_X, ODOM_POSE_Y, ODOM_TWIST: the pose rounded to the wire's units, each
        frame naming the WHEEL_ENCODERS COUNTER it includes."""
        ecu = self._ecu
        odo = ecu.odometry
        enc = ecu.encoders.enc_counter
        x_100um = mul_shr_round_i64(odo.x_q40_m, 10_000, 40, ecu.errors)
        y_100um = mul_shr_round_i64(odo.y_q40_m, 10_000, 40, ecu.errors)
        heading_rounded = odo.heading_bam64 + (1 << 47)  # u64 add: its carry is a whole turn
        heading_bam16 = (heading_rounded >> 48) & 0xFFFF
        turns = wrap_i32(odo.heading_turns + (heading_rounded >> 64))  # TURNS of the rounded value
        distance_mm = (odo.distance_q40_m * 1000 + (1 << 39)) >> 40
        e = ecu.errors
        tx = ecu.tx
        counter = tx.next_counter
        tx.send(
            fr.ODOM_POSE_X_ID,
            fr.pack_odom_pose_x(counter(fr.ODOM_POSE_X_ID), enc, x_100um, heading_bam16, e),
        )
        tx.send(
            fr.ODOM_POSE_Y_ID,
            fr.pack_odom_pose_y(counter(fr.ODOM_POSE_Y_ID), enc, y_100um, turns, e),
        )
        twist = ecu.twist
        data = fr.pack_odom_twist(
            counter(fr.ODOM_TWIST_ID), enc, twist.linear_mm_s, twist.angular_mrad_s, distance_mm, e
        )
        tx.send(fr.ODOM_TWIST_ID, data)

    def _send_status(self) -> None:
        """ODOM_STATUS: the summary page (a DEGRADED episode it carries may then recover),
        then the next rotating page."""
        ecu = self._ecu
        summary = fr.pack_odom_status_summary(
            ecu.tx.next_counter(fr.ODOM_STATUS_ID),
            ecu.health.state,
            ecu.odometry.consts.integrator,
            ecu.errors.bits,
            ecu.clock.uptime_s(),
            ecu.errors,
            ecu.health.reason,
        )
        ecu.health.summary_sent(ecu.tx.send(fr.ODOM_STATUS_ID, summary))
        page = _ROTATING_PAGES[self._page_index]
        self._page_index = (self._page_index + 1) % len(_ROTATING_PAGES)
        ecu.tx.send(fr.ODOM_STATUS_ID, self._status_page(page))

    def _status_page(self, page: fr.StatusPage) -> bytes:
        """One rotating page: the frame totals, one received message's E2E counts, or the
        profile the firmware runs with."""
        ecu = self._ecu
        counter = ecu.tx.next_counter(fr.ODOM_STATUS_ID)
        if page is fr.StatusPage.PROFILE:
            return fr.pack_odom_status_profile(
                counter, ecu.params.max_wheel_speed_mm_s, ecu.profile_crc
            )
        if page is fr.StatusPage.FRAME_TOTALS:
            return fr.pack_odom_status_frame_totals(
                counter, ecu.rx_encoders.lost_frames, ecu.frames_rejected, ecu.mailbox.overflows
            )
        rx = {
            fr.StatusPage.E2E_WHEEL_ENCODERS: ecu.rx_encoders,
            fr.StatusPage.E2E_ODOM_SET_POSE: ecu.rx_set_pose,
            fr.StatusPage.E2E_ODOM_CONFIG: ecu.rx_config,
            fr.StatusPage.E2E_NAV_GOAL: ecu.rx_nav_goal,
        }[page]
        return fr.pack_odom_status_e2e(
            counter,
            page,
            rx.accepted(),
            rx.lost_frames,
            rx.count_repeated,
            rx.count_error,
            rx.count_wrongsequence,
        )


def frames_rejected(bad_length: int, implausible: int, receivers: tuple[E2EReceiver, ...]) -> int:
    """Frames refused for their length, as implausible or by an E2E check (u32, wrapping)."""
    total = bad_length + implausible
    for rx in receivers:
        total += rx.count_error + rx.count_wrongsequence + rx.count_repeated
    return wrap_u32(total)
