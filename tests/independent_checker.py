"""An independent judge for the tests: float64 odometry written for them, cantools decoding.

Shares nothing with ``host.judge`` (no ``reference``, no ``analysis``, no ``host.io.logs``, no
bulk decoder): it reads the candump text with a regular expression, checks each frame's AUTOSAR
E2E Profile 2 CRC with a bitwise CRC8H2F of its own, decodes with ``cantools``'
``Database.decode_message`` one frame at a time, and integrates the wheel counts with
``math`` in plain float64:

* dS_L,R = delta * 2 pi r_L,R / PPV; dS = (dS_L + dS_R) / 2; the heading is the exact function of
  the cumulative counts, phi = phi0 + 2 pi (r_R N_R - r_L N_L) / (PPV b);
* euler: x += dS cos(phi_new); rk2: x += dS cos(phi_mid);
  exact: x += (dS / dtheta) (sin phi_new - sin phi_old) (the ICC arc, Taylor-expanded below
  |dtheta| = 1e-6 to dS cos(phi_mid) (1 - dtheta^2 / 24)), and likewise for y.

The start is told, not fitted: ``starts`` gives the firmware's true pose at the first encoder
frame of every segment (a segment starts at the log's first encoder frame and after every gap of
more than one period), e.g. from the synthesizer that wrote the log. An on-board sample is an
ODOM_POSE_X and ODOM_POSE_Y pair naming the same encoder frame (ENC_COUNTER = that frame's
COUNTER, the latest such frame in the log, if the log's latest encoder frame is less than 8
periods older than the pose: else which frame it names cannot be told); an encoder frame
repeating the COUNTER of its ID's previous frame is refused, as E2E Profile 2 refuses it (a
repetition, or 16 frames lost: the same to it), unless the checker is told the log's gaps are
the recorder's (the firmware had the frames between: ``recorder_gaps``).

The firmware's plausibility rule, from its specification (firmware/ecu.py's module docstring),
written again here: a step from the last accepted frame beyond ceil(v_max T / travel per count)
+ 1 counts per period elapsed on either wheel (v_max = 4 m/s, T = 10 ms) is refused, not
integrated, and the on-board pose keeps naming the last accepted frame; ``RESYNC`` refused frames
in a row, each plausible from the one before, are a counter restart: the odometry restarts from
the first of them and takes one step to the last (the jump itself is lost). A frame whose
CTRL_UPTIME (the motor controller's age) is below the last accepted frame's, both non-zero, comes
from a restarted controller, when its counts are within its age's travel at v_max of 0 and the
next frame confirms it (its COUNTER n = 1..15 ahead, its CTRL_UPTIME the same or one more, its
counts young too and within n periods' travel at v_max of the first's; a forged frame passing
the CRC is not confirmed and is refused): the odometry restarts on it, no step into it (the
DBC's comment), then goes on with the confirming frame.

A stalled firmware (no ODOM_POSE frame for ``SILENCE_PERIODS`` periods or more while at least
``SILENCE_PERIODS - 1`` encoder frames went by, firmware/ecu.py TIME_LOST): its first pose
after the silence names a frame of its backlog that ENC_COUNTER cannot tell, so it is not
compared; the firmware took the frames it missed as one step, so at the next accepted encoder
frame the position starts again where the firmware was (``starts``), as after a gap, and the
heading goes on following the counts. The verdict: max position distance <= one LSB (0.1 mm)
and max wrapped heading error <= one LSB (2 pi / 65536).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Collection
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import cantools
from cantools.database.can import Database

from odocan.sim.contract import DBC_PATH
from tests.dbc_typed import dbc_attribute

POSITION_LSB_M = 1e-4
HEADING_LSB_RAD = 2.0 * math.pi / 65536.0
PERIOD_S = 0.01
MAX_WHEEL_SPEED_M_S = 4.0  # the firmware's maximum rim speed when the robot states none
RESYNC = 3  # refused frames consistent among themselves: the counters restarted
SILENCE_PERIODS = 8  # no pose for this many periods while the encoder frames went on: a stall
# a candump line; python-can's writer adds the direction (" R" or " T")
_LINE = re.compile(r"\((\d+\.\d+)\) \S+ ([0-9A-Fa-f]+)#([0-9A-Fa-f]*)(?: [RT])?")


@dataclass(frozen=True)
class Robot:
    """The firmware's configuration, as ODOM_CONFIG carries it (nm, counts)."""

    counts_per_rev: int
    wheel_radius_left_nm: int
    wheel_radius_right_nm: int
    wheelbase_nm: int
    counter_bits: int
    max_wheel_speed_mm_s: int = round(MAX_WHEEL_SPEED_M_S * 1000)


@dataclass(frozen=True)
class Verdict:
    """The checker's comparison of the on-board poses with its own odometry."""

    samples: int
    max_position_error_m: float
    max_heading_error_rad: float

    @property
    def passed(self) -> bool:
        return (self.max_position_error_m <= POSITION_LSB_M
                and self.max_heading_error_rad <= HEADING_LSB_RAD)


def crc8h2f(data: bytes) -> int:
    """CRC8H2F, bit by bit: poly 0x2F, init 0xFF, no reflection, xorout 0xFF."""
    crc = 0xFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x2F) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc ^ 0xFF


class _Frames:
    """The log's E2E-valid frames decoded with cantools, in order. ``recorder_gaps``: the log's
    gaps are frames the recorder lost, the firmware had them: a WHEEL_ENCODERS frame repeating
    its previous frame's COUNTER half a COUNTER cycle (8 periods) or more after it is the
    sender's frame 16 k periods on, which the firmware took (no repetition to it)."""

    def __init__(self, path: Path, recorder_gaps: bool = False,
                 period_s: float = PERIOD_S) -> None:
        db = cantools.database.load_file(str(DBC_PATH))
        assert isinstance(db, Database)
        self.db = db
        self._ids = {m.frame_id: [int(v) for v in dbc_attribute(m, "E2EDataIDs").split(",")]
                     for m in db.messages}
        self.rows: list[tuple[float, str, dict[str, float | int]]] = []
        last_counter: dict[int, int] = {}
        last_t: dict[int, float] = {}
        encoders_id = db.get_message_by_name("WHEEL_ENCODERS").frame_id
        for line in path.read_text().splitlines():
            m = _LINE.fullmatch(line.strip())
            if m is None:
                continue
            can_id, data = int(m.group(2), 16), bytes.fromhex(m.group(3))
            if can_id not in self._ids or len(data) != 8:
                continue
            if crc8h2f(data[1:] + bytes([self._ids[can_id][data[1] & 0xF]])) != data[0]:
                continue
            t = float(m.group(1))
            cycled = (recorder_gaps and can_id == encoders_id
                      and t - last_t.get(can_id, t) >= 8 * period_s)
            if last_counter.get(can_id) == data[1] & 0xF and not cycled:
                continue  # E2E Profile 2: a repetition (or 16 frames lost: the same to it)
            last_counter[can_id], last_t[can_id] = data[1] & 0xF, t
            message = self.db.get_message_by_frame_id(can_id)
            signals = self.db.decode_message(can_id, data, decode_choices=False, scaling=False)
            self.rows.append((float(m.group(1)), message.name, dict(signals)))  # type: ignore[arg-type]


class _Odometry:
    """Plain float64 odometry of one robot (module docstring)."""

    def __init__(self, robot: Robot, integrator: str) -> None:
        self.integrator = integrator
        self.m_left = 2.0 * math.pi * robot.wheel_radius_left_nm * 1e-9 / robot.counts_per_rev
        self.m_right = 2.0 * math.pi * robot.wheel_radius_right_nm * 1e-9 / robot.counts_per_rev
        self.b = robot.wheelbase_nm * 1e-9
        self.x = self.y = self.phi0 = 0.0
        self.n_left = self.n_right = 0

    def place(self, x: float, y: float, heading: float) -> None:
        """Put the robot at a pose (the heading keeps being the function of the counts)."""
        self.x, self.y = x, y
        self.phi0 = heading - self.heading_offset()

    def heading_offset(self) -> float:
        return (self.n_right * self.m_right - self.n_left * self.m_left) / self.b

    @property
    def heading(self) -> float:
        return self.phi0 + self.heading_offset()

    def step(self, d_left: int, d_right: int) -> None:
        ds = 0.5 * (d_left * self.m_left + d_right * self.m_right)
        old = self.heading
        self.n_left += d_left
        self.n_right += d_right
        new = self.heading
        dtheta = new - old
        if self.integrator == "euler":
            self.x += ds * math.cos(new)
            self.y += ds * math.sin(new)
        elif self.integrator == "rk2" or abs(dtheta) < 1e-6:
            factor = 1.0 if self.integrator == "rk2" else 1.0 - dtheta * dtheta / 24.0
            self.x += ds * factor * math.cos(0.5 * (old + new))
            self.y += ds * factor * math.sin(0.5 * (old + new))
        else:
            self.x += ds / dtheta * (math.sin(new) - math.sin(old))
            self.y -= ds / dtheta * (math.cos(new) - math.cos(old))


_Stamp = tuple[float, int, int]  # (time s, left count, right count) of one encoder frame


class _Follower:
    """``check``'s walk along the encoder frames: the odometry, the firmware's plausibility
    rule and counter restarts, the recent (COUNTER, pose) pairs and the pose errors found."""

    def __init__(
        self, robot: Robot, integrator: str, starts: Callable[[float], tuple[float, float, float]],
        max_wheel_speed_m_s: float | None, reboots_t_s: Collection[float] = (),
        period_s: float = PERIOD_S,
    ) -> None:
        self.period_s = period_s  # the WHEEL_ENCODERS cycle (s)
        self.odo = _Odometry(robot, integrator)
        self.reboots_us = {round(t * 1e6) for t in reboots_t_s}
        self.starts = starts
        self.wire = 1 << min(robot.counter_bits, 24)
        self.recent: list[tuple[int, tuple[float, float, float]]] = []  # the last 16
        self.last_t = -math.inf  # the latest encoder frame's time
        self.halves: dict[tuple[str, int], dict[str, float]] = {}
        self.prev: _Stamp | None = None
        self.errors: list[tuple[float, float]] = []
        self.bound = [math.inf if max_wheel_speed_m_s is None
                      else math.ceil(max_wheel_speed_m_s * period_s / m) + 1
                      for m in (self.odo.m_left, self.odo.m_right)]
        self.refused: list[_Stamp] = []  # the run of refused frames, each plausible
        self.last_pose_t = -math.inf  # the latest pose frame's time
        self.heard_since_pose = 0  # encoder frames since it
        self.resumed_t: float | None = None  # a stall ended: pose frames at this time are skipped
        self.place_next = False  # ... and the position starts again at the next encoder frame
        self.uptime = 0  # CTRL_UPTIME of the last accepted frame
        self.held: tuple[_Stamp, dict[str, float | int]] | None = None  # a restart's first frame

    def pose_frame(self, t: float) -> bool:
        """Whether a pose frame at ``t`` s may be compared (False: the first after a stall)."""
        silent = t - self.last_pose_t >= (SILENCE_PERIODS - 0.5) * self.period_s
        if silent and self.heard_since_pose >= SILENCE_PERIODS - 1 and self.prev is not None:
            self.resumed_t, self.place_next = t, True
            self.halves.clear()
        self.last_pose_t, self.heard_since_pose = t, 0
        return t != self.resumed_t

    def deltas(self, a: _Stamp, b: _Stamp) -> tuple[int, int]:
        wire = self.wire
        return ((b[1] - a[1] + wire // 2) % wire - wire // 2,
                (b[2] - a[2] + wire // 2) % wire - wire // 2)

    def _young(self, frame: _Stamp, uptime: int) -> bool:
        """A restarted controller's counts: from 0, at most ``uptime`` s of travel at v_max."""
        wire = self.wire
        per_s = round(1.0 / self.period_s)  # periods in one second of CTRL_UPTIME
        return all(abs((c + wire // 2) % wire - wire // 2) <= uptime * per_s * b
                   for c, b in zip(frame[1:], self.bound, strict=True))

    def _confirms(self, held: tuple[_Stamp, dict[str, float | int]], frame: _Stamp,
                  s: dict[str, float | int]) -> bool:
        """``frame`` (signals ``s``) confirms the ``held`` restart frame."""
        first, first_s = held
        n = (int(s["COUNTER"]) - int(first_s["COUNTER"])) % 16
        age, first_age = int(s.get("CTRL_UPTIME", 0)), int(first_s.get("CTRL_UPTIME", 0))
        d = self.deltas(first, frame)
        return (n > 0 and first_age <= age <= first_age + 1 and self._young(frame, age)
                and abs(d[0]) <= n * self.bound[0] and abs(d[1]) <= n * self.bound[1])

    def plausible(self, a: _Stamp, b: _Stamp) -> bool:
        periods = max(1, round((b[0] - a[0]) / self.period_s))
        d = self.deltas(a, b)
        return abs(d[0]) <= periods * self.bound[0] and abs(d[1]) <= periods * self.bound[1]

    def encoders(self, t: float, s: dict[str, float | int]) -> None:
        """One WHEEL_ENCODERS frame at ``t`` s."""
        frame = (t, int(s["LEFT_COUNT"]), int(s["RIGHT_COUNT"]))
        self.last_t = t
        self.heard_since_pose += 1
        self.halves.clear()
        if round(t * 1e6) in self.reboots_us:  # a new firmware: primed on this frame; the
            self.prev, self.refused, self.held = None, [], None  # silence of its boot before
            self.last_pose_t, self.heard_since_pose = t, 0  # it was no stall (none to place)
        uptime = int(s.get("CTRL_UPTIME", 0))
        held, self.held = self.held, None
        if held is not None and self._confirms(held, frame, s):
            self.refused = []
            self._accept(*held)  # the odometry restarts on the held frame: no step into it
        elif self.prev is not None and 0 < uptime < self.uptime and self._young(frame, uptime):
            self.held = (frame, s)  # a restart if the next frame confirms it: a pose naming
            odo = self.odo  # it is the pose before (no step into it), as the firmware's would be
            self.recent = [(int(s["COUNTER"]), (odo.x, odo.y, odo.heading)), *self.recent][:16]
            return
        if self.prev is not None and not self.plausible(self.prev, frame):
            self._refuse(frame, s)
            return
        self.refused = []
        if self.prev is None:
            self.odo.place(*self.starts(t))
        else:
            self._advance(self.prev, frame)
        self._accept(frame, s)

    def _refuse(self, frame: _Stamp, s: dict[str, float | int]) -> None:
        """An implausible frame; the ``RESYNC``-th in a run is a counter restart."""
        consistent = bool(self.refused) and self.plausible(self.refused[-1], frame)
        self.refused = [*self.refused, frame] if consistent else [frame]
        if len(self.refused) < RESYNC:
            return
        self.odo.step(*self.deltas(self.refused[0], frame))  # restarted: from the first, one step
        self.refused = []
        self._accept(frame, s)

    def _advance(self, prev: _Stamp, frame: _Stamp) -> None:
        d_left, d_right = self.deltas(prev, frame)
        if frame[0] - prev[0] > 1.5 * self.period_s or self.place_next:  # a gap or a stall: the
            self.place_next = False  # heading follows the counts,
            self.odo.n_left += d_left  # the position starts again where the firmware was
            self.odo.n_right += d_right
            self.odo.x, self.odo.y = self.starts(frame[0])[:2]
        else:
            self.odo.step(d_left, d_right)

    def _accept(self, frame: _Stamp, s: dict[str, float | int]) -> None:
        self.prev = frame
        self.uptime = int(s.get("CTRL_UPTIME", 0))
        odo = self.odo
        self.recent = [(int(s["COUNTER"]), (odo.x, odo.y, odo.heading)), *self.recent][:16]


def check(
    path: Path, robot: Robot, integrator: str,
    starts: Callable[[float], tuple[float, float, float]],
    max_wheel_speed_m_s: float | Literal["robot"] | None = "robot",
    reboots_t_s: Collection[float] = (),
    recorder_gaps: bool = False,
    period_s: float = PERIOD_S,
) -> Verdict:
    """Compare the on-board poses of the log at ``path`` with this checker's odometry started
    at ``starts(timestamp of the segment's first encoder frame)`` (module docstring);
    ``max_wheel_speed_m_s`` None: no plausibility rule (drives faster than any ECU allows);
    "robot": the robot's own (``Robot.max_wheel_speed_mm_s``);
    ``reboots_t_s``: encoder frames (their times) a rebooted firmware primed on;
    ``recorder_gaps``: the log's gaps are the recorder's (``_Frames``);
    ``period_s``: the WHEEL_ENCODERS cycle the firmware runs at (its DBC's)."""
    frames = _Frames(path, recorder_gaps, period_s)
    if max_wheel_speed_m_s == "robot":
        max_wheel_speed_m_s = robot.max_wheel_speed_mm_s / 1000
    walk = _Follower(robot, integrator, starts, max_wheel_speed_m_s, reboots_t_s, period_s)
    for t, name, s in frames.rows:
        if name == "WHEEL_ENCODERS":
            walk.encoders(t, s)
        elif name in ("ODOM_POSE_X", "ODOM_POSE_Y") and walk.pose_frame(t) \
                and t - walk.last_t < 8 * period_s:
            _pair(name, s, walk.recent, walk.halves, walk.errors)
    errors = walk.errors
    if not errors:
        return Verdict(0, math.nan, math.nan)
    return Verdict(len(errors), max(e[0] for e in errors), max(e[1] for e in errors))


def _pair(
    name: str, s: dict[str, float | int], recent: list[tuple[int, tuple[float, float, float]]],
    halves: dict[tuple[str, int], dict[str, float]], errors: list[tuple[float, float]],
) -> None:
    """File one pose half; when both halves of one encoder frame are in, record its errors."""
    named = int(s["ENC_COUNTER"])
    pose = next((p for c, p in recent if c == named), None)
    if pose is None:
        return
    halves.setdefault((name, named), {k: float(v) for k, v in s.items()})
    x_half, y_half = halves.get(("ODOM_POSE_X", named)), halves.get(("ODOM_POSE_Y", named))
    if x_half is None or y_half is None:
        return
    x, y = x_half["X"] * POSITION_LSB_M, y_half["Y"] * POSITION_LSB_M
    heading = y_half["TURNS"] * 2.0 * math.pi + x_half["HEADING"] * HEADING_LSB_RAD
    dh = (heading - pose[2] + math.pi) % (2.0 * math.pi) - math.pi
    errors.append((math.hypot(x - pose[0], y - pose[1]), abs(dh)))
    del halves[("ODOM_POSE_X", named)], halves[("ODOM_POSE_Y", named)]
