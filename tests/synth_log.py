"""Candump logs written directly (not simulated in real time) with the firmware's exact outputs.

A drive is a sequence of count deltas per encoder period (10 ms). ``synthesize`` runs the
firmware's own ``Odometry`` on the wrapping counters and packs the frames the ECU would send with
the firmware codec (``firmware.frames``, E2E protected), rounding the pose exactly as the ECU's
``_send_pose_and_twist`` does:

* WHEEL_ENCODERS every 10 ms (the low min(counter_bits, 24) bits of each counter);
* ODOM_POSE_X / ODOM_POSE_Y every other encoder frame, naming it (ENC_COUNTER), 1 ms after it;
* ODOM_STATUS page 0 (STATE OK, the integrator, UPTIME) every 10th encoder frame, and the page
  of WHEEL_ENCODERS E2E counts (ENC_E2E_OK: every frame so far) at frames 10, 60, 110, ...

The firmware starts at pose 0 on the first frame (power-up). ``counter_jumps`` restarts the
motor controller's counters (a reboot: the counts jump by an offset): the firmware refuses the
first ``RESYNC_FRAMES - 1`` frames after the jump (its pose still names the last accepted frame),
then re-primes on the first of them and integrates one step from it (COUNTER_RESET, firmware/ecu.py
module docstring); the jump itself is never integrated. ``reboot_at`` restarts the firmware at an
encoder frame (a new ECU on the same bus): its pose restarts at 0 primed on that frame, its E2E
counters and UPTIME at 0; its first ODOM_STATUS summary (UPTIME 0, STATE OK: it accepted the frame
in its first tick, as on the rig) follows that frame; or, ``boot_in_init``, its first summary
(STATE INIT, UPTIME 0) comes 5 ms before that frame. ``Synth.lines(start)`` cuts the log at
an encoder frame to make a log that starts mid-drive; ``Synth.state[k]`` is the firmware's
internal pose after encoder frame k (Q40 metres, BAM64 + whole turns) to compare against.
``ctrl_restarts`` restarts the motor controller at an encoder frame with a jump of its counters
that fits the plausibility bound: with ``ctrl_uptime`` its frames carry CTRL_UPTIME (its age, 1
from the restart) and the firmware re-primes on that frame (COUNTER_RESET, the jump never
integrated), unless ``integrates_restarts`` (a wrong firmware, or an old controller's 0: the
counts alone cannot tell).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from odocan.firmware import frames as fr
from odocan.firmware.config import Integrator, RobotParams, derive_constants
from odocan.firmware.ecu import RECOVERY_FRAMES, RESYNC_FRAMES, WATCHDOG_TICKS
from odocan.firmware.errors import ErrorMask, Reason, State
from odocan.firmware.fixmath import mul_shr_round_i64, wrap_i32
from odocan.firmware.odometry import Odometry
from odocan.firmware.twist import Twist
from odocan.sim import frames as sf
from odocan.sim.robot import RobotProfile

ENCODER_PERIOD_S = 0.01
WIRE_BITS = 24
INTEGRATORS = {"euler": Integrator.EULER, "rk2": Integrator.RK2, "exact": Integrator.EXACT}
TWO_POW_40 = float(1 << 40)
BAM64_TO_RAD = 2.0 * math.pi / 2.0**64


@dataclass(frozen=True)
class FirmwareState:
    """The firmware's pose after one encoder frame (its internal integers)."""

    x_q40_m: int
    y_q40_m: int
    heading_bam64: int
    heading_turns: int

    @property
    def pose(self) -> tuple[float, float, float]:
        """(x m, y m, unwrapped heading rad)."""
        heading = self.heading_turns * 2.0 * math.pi + self.heading_bam64 * BAM64_TO_RAD
        return self.x_q40_m / TWO_POW_40, self.y_q40_m / TWO_POW_40, heading


@dataclass
class Synth:
    """A synthesized drive: one candump line per frame, grouped by encoder frame."""

    groups: list[list[str]] = field(default_factory=list)  # lines of encoder frame k and after
    state: list[FirmwareState] = field(default_factory=list)
    left_counts: list[int] = field(default_factory=list)  # the hardware counters (counter_bits)
    right_counts: list[int] = field(default_factory=list)

    def lines(self, start: int = 0, stop: int | None = None) -> list[str]:
        """The log from encoder frame ``start`` (inclusive) to ``stop`` (exclusive)."""
        return [line for group in self.groups[start:stop] for line in group]

    def write(self, path: Path, start: int = 0, stop: int | None = None) -> Path:
        """Write the candump log (``candump -L`` format) and return its path."""
        path.write_text("".join(self.lines(start, stop)))
        return path


def _line(t_s: float, can_id: int, data: bytes) -> str:
    return f"({t_s:.6f}) vcan0 {can_id:03X}#{data.hex().upper()}\n"


def params_of(robot: RobotProfile, integrator: str) -> RobotParams:
    """The firmware's configuration of ``robot``."""
    return RobotParams(integrator=int(INTEGRATORS[integrator]), **robot.firmware_params())


def synthesize(
    robot: RobotProfile,
    integrator: str,
    d_left: npt.ArrayLike,
    d_right: npt.ArrayLike,
    *,
    counts0: tuple[int, int] = (0, 0),
    t0_s: float = 0.0,
    x_bias_100um: dict[int, int] | None = None,
    heading_bias_lsb: dict[int, int] | None = None,
    counter_jumps: dict[int, int] | None = None,
    reboot_at: int | None = None,
    boot_in_init: bool = False,
    ctrl_restarts: dict[int, tuple[int, int]] | None = None,
    ctrl_uptime: bool = False,
    integrates_restarts: bool = False,
    y_bias_100um: dict[int, int] | None = None,
    twist: bool = False,
    distance_of: Callable[[int, int, Odometry], int] | None = None,
    firmware_lost: set[int] | None = None,
    totals_at: frozenset[int] = frozenset(),
) -> Synth:
    """The frames of a drive of ``len(d_left)`` steps (``len + 1`` encoder frames).
    ``x_bias_100um``: a wrong firmware, whose X at encoder frame k is off by that many LSB;
    ``heading_bias_lsb``: ... whose HEADING (and TURNS) at encoder frame k is off by that many;
    ``y_bias_100um``: ... whose Y at encoder frame k is off by that many LSB.
    ``counter_jumps``: {encoder frame: offset in counts} where both counters restart (the jumps
    at least ``RESYNC_FRAMES`` frames apart and beyond the plausibility bound).
    ``reboot_at``: the encoder frame the firmware restarts on (module docstring);
    ``boot_in_init``: it booted 5 ms before that frame, its first summary saying INIT.
    ``ctrl_restarts``: {encoder frame: (left, right) jump in counts} where the motor controller
    restarted (module docstring); ``ctrl_uptime``: its frames carry CTRL_UPTIME (else 0);
    ``integrates_restarts``: the firmware integrates the jump.
    ``twist``: ODOM_TWIST with each pose pair (speeds from the firmware's ``Twist``, DISTANCE
    rounded as ``reports._send_pose_and_twist`` does); ``distance_of(k, distance_mm, odo)``: a
    wrong firmware's DISTANCE (mm) at encoder frame k instead.
    ``firmware_lost``: encoder frames the firmware lost (its mailbox dropped them) while the
    bus, and the log, carried them: not integrated (the next frame is one merged step) and
    counted in ENC_E2E_LOST, not ENC_E2E_OK.
    ``totals_at``: frames of the life (multiples of 10, not 10 mod 50) whose summary a
    FRAME_TOTALS page follows (nothing lost, refused or overflowed: not with ``firmware_lost``)."""
    if totals_at and firmware_lost:
        raise ValueError("totals_at says nothing was lost: not with firmware_lost")
    bias = x_bias_100um or {}
    lost_frames = firmware_lost or set()
    lost = 0  # encoder frames the running firmware lost since it primed
    jumps = counter_jumps or {}
    named = 0  # the COUNTER of the last encoder frame the firmware accepted
    resync_first: tuple[int, int] | None = None
    resync_until = -1
    errors = ErrorMask()
    odo = Odometry(derive_constants(params_of(robot, integrator), errors), errors)
    bits = robot.counter_bits
    mask, wire_mask = (1 << bits) - 1, (1 << min(bits, WIRE_BITS)) - 1
    left, right = counts0[0] & mask, counts0[1] & mask
    dl = np.concatenate(([0], np.asarray(d_left, dtype=np.int64)))
    dr = np.concatenate(([0], np.asarray(d_right, dtype=np.int64)))
    out = Synth()
    pose_counter = status_counter = 0
    boot = 0  # the encoder frame the running firmware primed on
    controller = _Controller(ctrl_restarts or {}, ctrl_uptime, integrates_restarts)
    speeds = Twist(odo, errors)
    for k in range(len(dl)):
        if k == reboot_at:  # a new firmware: pose 0, E2E counters and UPTIME from 0
            errors = ErrorMask()
            odo = Odometry(derive_constants(params_of(robot, integrator), errors), errors)
            speeds = Twist(odo, errors)
            pose_counter = status_counter = lost = 0
            boot = k
        left, right = (left + int(dl[k])) & mask, (right + int(dr[k])) & mask
        if k in jumps:  # the motor controller restarts its counters
            left, right = (left + jumps[k]) & mask, (right + jumps[k]) & mask
            resync_first, resync_until = (left, right), k + RESYNC_FRAMES - 1
        (left, right), uptime = controller.frame(k, (left, right), mask, odo)
        if k in lost_frames:
            lost += 1  # never in its mailbox: the next frame it takes shows the COUNTER skip
        elif _takes(odo, speeds, k, (left, right), (resync_first, resync_until)):
            named = k & 0xF
        t_s = t0_s + k * ENCODER_PERIOD_S
        group = [_line(t_s, fr.WHEEL_ENCODERS_ID,
                       sf.pack_wheel_encoders(k, left & wire_mask, right & wire_mask, uptime))]
        life = k - boot  # frames since the firmware primed
        if boot_in_init and k == reboot_at:  # booted before the frame: INIT, no pose yet
            init = fr.pack_odom_status_summary(0, State.INIT, odo.consts.integrator, 0, 0, errors)
            group.insert(0, _line(t_s - 0.005, fr.ODOM_STATUS_ID, init))
            status_counter = 1
        if life % 2 == 0:
            group += _pose_lines(odo, t_s + 0.001, pose_counter, named, errors, bias.get(k, 0),
                                 (heading_bias_lsb or {}).get(k, 0),
                                 (y_bias_100um or {}).get(k, 0))
            group += [_twist_line(odo, speeds, t_s + 0.001, pose_counter, named, errors, k,
                                  distance_of)] if twist else []
            pose_counter += 1
        if life % 10 == 0 and not (boot_in_init and k == reboot_at):
            uptime_s = int(life * ENCODER_PERIOD_S + (t0_s if boot == 0 else 0.0))
            status = fr.pack_odom_status_summary(
                status_counter, State.OK, odo.consts.integrator, 0, uptime_s, errors
            )
            group.append(_line(t_s + 0.001, fr.ODOM_STATUS_ID, status))
            status_counter += 1
        pages = _pages(life, status_counter, lost, life in totals_at)
        group += [_line(t_s + 0.001, fr.ODOM_STATUS_ID, page) for page in pages]
        status_counter += len(pages)
        out.groups.append(group)
        out.state.append(
            FirmwareState(odo.x_q40_m, odo.y_q40_m, odo.heading_bam64, odo.heading_turns)
        )
        out.left_counts.append(left)
        out.right_counts.append(right)
    return out


@dataclass
class _Controller:
    """The motor controller's restarts (``synthesize``'s ``ctrl_restarts``, ``ctrl_uptime``,
    ``integrates_restarts``) and the frame it (re)started at."""

    restarts: dict[int, tuple[int, int]]
    reports_uptime: bool
    integrates: bool
    powered_up: int = 0

    def frame(self, k: int, counts: tuple[int, int], mask: int, odo: Odometry
              ) -> tuple[tuple[int, int], int]:
        """Encoder frame ``k``'s counters (jumped at a restart; the firmware re-primes ``odo``
        when CTRL_UPTIME goes back from 2+ to 1) and its CTRL_UPTIME."""
        jump = self.restarts.get(k)
        if jump is not None:
            counts = (counts[0] + jump[0]) & mask, (counts[1] + jump[1]) & mask
            if self.reports_uptime and k - self.powered_up >= 100 and not self.integrates:
                odo.unprime()
            self.powered_up = k
        age_s = (k - self.powered_up) // 100
        return counts, min(15, 1 + age_s) if self.reports_uptime else 0


def _takes(odo: Odometry, speeds: Twist, k: int, counts: tuple[int, int],
           resync: tuple[tuple[int, int] | None, int]) -> bool:
    """Whether the firmware integrates encoder frame ``k`` (``counts``), and does so: frames
    before a counter restart's re-prime frame (``resync``: the first counts after the jump and
    that frame) are refused, beyond the plausibility bound from the last accepted frame; on
    that frame it re-primes (COUNTER_RESET)."""
    first, until = resync
    if k < until:
        return False
    if k == until and first is not None:
        odo.unprime()
        odo.step_counts(*first)
    _integrate(odo, speeds, *counts)
    return True


def _pages(life: int, counter: int, lost: int, totals: bool) -> list[bytes]:
    """The ODOM_STATUS pages after the summary of the life's frame ``life`` (from E2E COUNTER
    ``counter``): the E2E counts of the encoder frames (life + 1 seen, ``lost`` of them lost) at
    10 mod 50, the FRAME_TOTALS page (nothing lost, refused or overflowed) when ``totals``."""
    pages = []
    if life % 50 == 10:
        pages.append(fr.pack_odom_status_e2e(
            counter, fr.StatusPage.E2E_WHEEL_ENCODERS, life + 1 - lost, lost, 0, 0, 0))
    if totals:
        pages.append(fr.pack_odom_status_frame_totals(counter + len(pages), 0, 0, 0))
    return pages


def _integrate(odo: Odometry, speeds: Twist, left: int, right: int) -> None:
    """One step of the counters, summed into the twist when integrated."""
    if odo.step_counts(left, right):
        speeds.sum_step(1)


def _twist_line(odo: Odometry, speeds: Twist, t_s: float, counter: int, enc: int,
                errors: ErrorMask, k: int,
                distance_of: Callable[[int, int, Odometry], int] | None) -> str:
    """ODOM_TWIST as the ECU sends it (its speeds over the steps since the last one)."""
    if speeds.steps:
        speeds.update(max(speeds.tick_periods, 1))
    distance_mm = (odo.distance_q40_m * 1000 + (1 << 39)) >> 40
    if distance_of is not None:
        distance_mm = distance_of(k, distance_mm, odo)
    data = fr.pack_odom_twist(counter, enc, speeds.linear_mm_s, speeds.angular_mrad_s,
                              distance_mm, errors)
    return _line(t_s, fr.ODOM_TWIST_ID, data)


def _pose_lines(
    odo: Odometry, t_s: float, counter: int, enc: int, errors: ErrorMask, x_bias_100um: int = 0,
    heading_bias_lsb: int = 0, y_bias_100um: int = 0,
) -> list[str]:
    """ODOM_POSE_X and ODOM_POSE_Y, rounded as the ECU rounds them (X off by ``x_bias_100um``,
    the heading by ``heading_bias_lsb``, Y by ``y_bias_100um``)."""
    x_100um = mul_shr_round_i64(odo.x_q40_m, 10_000, 40, errors) + x_bias_100um
    y_100um = mul_shr_round_i64(odo.y_q40_m, 10_000, 40, errors) + y_bias_100um
    heading_rounded = odo.heading_bam64 + (1 << 47) + (heading_bias_lsb << 48)
    heading_bam16 = (heading_rounded >> 48) & 0xFFFF
    turns = wrap_i32(odo.heading_turns + (heading_rounded >> 64))
    pose_x = fr.pack_odom_pose_x(counter, enc, x_100um, heading_bam16, errors)
    pose_y = fr.pack_odom_pose_y(counter, enc, y_100um, turns, errors)
    return [_line(t_s, fr.ODOM_POSE_X_ID, pose_x), _line(t_s, fr.ODOM_POSE_Y_ID, pose_y)]


def wandering_drive(
    robot: RobotProfile, steps: int, step_m: float, seed: int
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Count deltas of a drive of straight runs and arcs of both senses (about ``step_m`` per
    step), turning back now and then so that it wanders instead of running away."""
    rng = np.random.default_rng(seed)
    mean_radius_m = 0.5 * (robot.wheel_radius_left_m + robot.wheel_radius_right_m)
    per_count = 2.0 * math.pi * mean_radius_m / robot.counts_per_rev
    base = step_m / per_count
    segment = rng.integers(50, 400, size=steps // 50 + 2)
    curvature = rng.choice([0.0, 0.0, 0.01, -0.01, 0.05, -0.05, 0.002], size=len(segment))
    idx = np.repeat(np.arange(len(segment)), segment)[:steps]
    diff = curvature[idx] * base
    noise = rng.normal(0.0, 0.01 * base, size=steps)
    d_left = np.rint(base - diff + noise).astype(np.int64)
    d_right = np.rint(base + diff + noise).astype(np.int64)
    return d_left, d_right


STALL_FIFO_FRAMES = 3  # the CAN controller's receive FIFO: the frames a stalled MCU still gets


@dataclass
class _Pace:
    """What the firmware does at one encoder frame of ``synthesize_stalled``."""

    silent: bool = False  # no tick runs: nothing integrated, nothing sent
    steps: list[int] = field(default_factory=list)  # encoder frames integrated in this tick
    reason: Reason = Reason.NONE


def _paces(
    n_frames: int, stalls: dict[int, int], holds: dict[int, int], late: set[int]
) -> list[_Pace]:
    """Per encoder frame: silent or not, the frames integrated, the reason reported."""
    paces = [_Pace(steps=[k]) for k in range(n_frames)]
    for k in sorted(late):
        if k + 1 < n_frames:
            paces[k].steps.remove(k)
            paces[k + 1].steps.insert(0, k)
    for k, n in stalls.items():
        for j in range(k, min(k + n, n_frames)):
            paces[j] = _Pace(silent=True)
        if k + n < n_frames:  # resume: the FIFO's oldest frames (stale), then fresh ones
            paces[k + n] = _Pace(steps=list(range(k, k + STALL_FIFO_FRAMES)),
                                 reason=Reason.TIME_LOST)
        for j in range(k + n + 1, min(k + n + 1 + RECOVERY_FRAMES, n_frames)):
            paces[j].reason = Reason.TIME_LOST
    for k, n in holds.items():
        for j in range(k, min(k + n, n_frames)):
            paces[j] = _Pace(reason=Reason.ENCODER_TIMEOUT if j - k >= WATCHDOG_TICKS
                             else Reason.NONE)
        for j in range(k + n, min(k + n + RECOVERY_FRAMES, n_frames)):
            paces[j].reason = Reason.ENCODER_TIMEOUT if n >= WATCHDOG_TICKS else Reason.NONE
    return paces


def synthesize_stalled(
    robot: RobotProfile,
    integrator: str,
    d_left: npt.ArrayLike,
    d_right: npt.ArrayLike,
    *,
    stalls: dict[int, int] | None = None,
    holds: dict[int, int] | None = None,
    x_bias_100um: dict[int, int] | None = None,
    late: set[int] | None = None,
) -> Synth:
    """Like ``synthesize`` (power-up, no counter jumps), with a firmware that stops keeping pace:

    * ``stalls`` {k: n}: the MCU stalls from encoder frame k for n frames (n >= 8): no tick runs,
      nothing is sent, while the motor controller goes on. Resuming at frame k + n, its first
      tick takes the ``STALL_FIFO_FRAMES`` frames its CAN FIFO held (k, k + 1, k + 2: the rest
      overran) and sends a pose naming the last of them (a backlog frame); frame k + n + 1 is
      then one step from it across the frames missed. ODOM_STATUS: DEGRADED (TIME_LOST) until
      ``RECOVERY_FRAMES`` frames later, then OK, as firmware/ecu.py does.
    * ``holds`` {k: n}: the firmware goes on ticking and sending but accepts none of frames
      k .. k + n - 1 (its E2E window shut after a late frame and a lost one): its poses keep
      naming frame k - 1; frame k + n is one step across them (DEGRADED, ENCODER_TIMEOUT, after
      ``WATCHDOG_TICKS`` frames).
    * ``late``: frames that reach the firmware a tick after their period (integrated then).
    * ``x_bias_100um``: a wrong firmware, as in ``synthesize``.

    ``Synth.state[k]`` is the firmware's pose after the tick of frame k (unchanged while silent
    or held)."""
    errors = ErrorMask()
    odo = Odometry(derive_constants(params_of(robot, integrator), errors), errors)
    mask, wire_mask = (1 << robot.counter_bits) - 1, (1 << min(robot.counter_bits, WIRE_BITS)) - 1
    dl = np.concatenate(([0], np.asarray(d_left, dtype=np.int64)))
    dr = np.concatenate(([0], np.asarray(d_right, dtype=np.int64)))
    left, right = np.cumsum(dl) & mask, np.cumsum(dr) & mask
    paces = _paces(len(dl), stalls or {}, holds or {}, late or set())
    out = Synth()
    named, accepted = 0, 0
    pose_counter = status_counter = 0
    for k, pace in enumerate(paces):
        for j in pace.steps:
            odo.step_counts(int(left[j]), int(right[j]))
            named, accepted = j & 0xF, accepted + 1
        t_s = k * ENCODER_PERIOD_S
        group = [_line(t_s, fr.WHEEL_ENCODERS_ID, sf.pack_wheel_encoders(
            k, int(left[k]) & wire_mask, int(right[k]) & wire_mask))]
        resumed = k > 0 and paces[k - 1].silent and not pace.silent
        if not pace.silent and (k % 2 == 0 or resumed):
            group += _pose_lines(odo, t_s + 0.001, pose_counter, named, errors,
                                 (x_bias_100um or {}).get(k, 0))
            pose_counter += 1
        if not pace.silent and (k % 10 == 0 or resumed):
            state = State.OK if pace.reason is Reason.NONE else State.DEGRADED
            status = fr.pack_odom_status_summary(status_counter, state, odo.consts.integrator, 0,
                                                 int(t_s), errors, int(pace.reason))
            group.append(_line(t_s + 0.001, fr.ODOM_STATUS_ID, status))
            status_counter += 1
        if not pace.silent and k % 50 == 10:
            page = fr.pack_odom_status_e2e(
                status_counter, fr.StatusPage.E2E_WHEEL_ENCODERS, accepted, 0, 0, 0, 0
            )
            group.append(_line(t_s + 0.001, fr.ODOM_STATUS_ID, page))
            status_counter += 1
        out.groups.append(group)
        out.state.append(
            FirmwareState(odo.x_q40_m, odo.y_q40_m, odo.heading_bam64, odo.heading_turns)
        )
        out.left_counts.append(int(left[k]))
        out.right_counts.append(int(right[k]))
    return out
