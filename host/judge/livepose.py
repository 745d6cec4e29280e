"""The live judge's poses and their errors (``host.judge.tracking``): a pose at the encoder frame
it names, a sample, the step gate that refuses implausible encoder steps as the firmware does, and
the running error statistics."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, NamedTuple

from odocan.firmware.encoders import MAX_WHEEL_SPEED_MM_S, RESYNC_FRAMES
from odocan.firmware.twist import ENCODER_PERIOD_US
from odocan.host.judge.reference import Geometry, wrap_delta
from odocan.host.protocol.pose import heading_fields, unwrap_near
from odocan.sim.pose import wrap_angle

RING = 16  # one slot per E2E COUNTER value of WHEEL_ENCODERS
ENCODER_PERIOD_S = ENCODER_PERIOD_US * 1e-6
CYCLES_AFTER_S = (RING // 2) * ENCODER_PERIOD_S  # below, ``step_periods`` adds no cycle


class Sample(NamedTuple):
    """An on-board sample settled: the pose, the reference at its encoder frame (None when
    unknown), the ENC_COUNTER it names, its ODOM_POSE_X's COUNTER and its ODOM_POSE_Y's bus
    time (s)."""

    pose: FramePose
    reference: FramePose | None
    enc_counter: int
    counter: int
    t_s: float


class StepGate:
    """The firmware's plausibility rule on the reference's steps (firmware/ecu.py, the same as
    ``host.judge.analysis``): a frame beyond ``MAX_WHEEL_SPEED_MM_S`` over the periods its COUNTER
    advanced since the last accepted one is refused; ``RESYNC_FRAMES`` refused frames plausible
    among themselves are a counter restart: one step from the first of them, never the jump.

    The periods of a step are the COUNTER advance plus the whole COUNTER cycles nearest to the
    bus time since the last accepted frame (``step_periods``), as the firmware counts them with
    its clock (``firmware.encoders._step_periods``): after a silence of the encoder node (its
    bus off, a sim SIGSTOPped) the first frame carries the distance driven meanwhile, which the
    firmware integrates as one long step; bounded by the COUNTER advance alone, that step was
    refused and taken for a counter restart (the distance dropped, a false POSE WRONG)."""

    def __init__(self, geometry: Geometry, counter_bits: int) -> None:
        travel_m = MAX_WHEEL_SPEED_MM_S * 1e-3 * ENCODER_PERIOD_US * 1e-6
        self.bound = (math.ceil(travel_m / geometry.m_per_count_left) + 1,
                      math.ceil(travel_m / geometry.m_per_count_right) + 1)
        self.bits = counter_bits
        self.prev: tuple[int, int, int] | None = None  # counter, left, right of the last accepted
        self.prev_t_s: float | None = None  # bus time of the last accepted frame (s)
        self._refused: list[tuple[int, int, int]] = []
        self.counter_restarts = 0

    def _delta(self, a: tuple[int, int, int], b: tuple[int, int, int]) -> tuple[int, int]:
        return wrap_delta(b[1] - a[1], self.bits), wrap_delta(b[2] - a[2], self.bits)

    def _plausible(self, a: tuple[int, int, int], b: tuple[int, int, int]) -> bool:
        periods = ((b[0] - a[0]) % RING) or RING
        d = self._delta(a, b)
        return abs(d[0]) <= periods * self.bound[0] and abs(d[1]) <= periods * self.bound[1]

    def step(self, counter: int, left: int, right: int,
             t_s: float | None = None) -> tuple[int, int] | None:
        """The count step to integrate for this frame, heard at bus time ``t_s`` (s; None: the
        COUNTER advance alone); None when it primes or is refused."""
        frame = (counter, left, right)
        prev, self.prev = self.prev, frame
        prev_t_s, self.prev_t_s = self.prev_t_s, t_s
        if prev is None:
            return None
        delta = self._delta(prev, frame)  # ``_plausible`` inlined: the delta computed once
        periods = ((counter - prev[0]) % RING) or RING
        if t_s is not None and prev_t_s is not None and t_s - prev_t_s > CYCLES_AFTER_S:
            periods = step_periods(periods, prev_t_s, t_s)
        if abs(delta[0]) <= periods * self.bound[0] and abs(delta[1]) <= periods * self.bound[1]:
            if self._refused:
                self._refused = []
            return delta
        self.prev, self.prev_t_s = prev, prev_t_s  # refused: the base stays
        consistent = bool(self._refused) and self._plausible(self._refused[-1], frame)
        self._refused = [*self._refused, frame] if consistent else [frame]
        if len(self._refused) < RESYNC_FRAMES:
            return None
        first, self._refused, self.prev, self.prev_t_s = self._refused[0], [], frame, t_s
        self.counter_restarts += 1
        return self._delta(first, frame)


def step_periods(advance: int, prev_t_s: float | None, t_s: float | None) -> int:
    """The encoder periods between two frames: the COUNTER ``advance`` (1..16) plus the whole
    COUNTER cycles that bring it nearest to the bus time between them (``prev_t_s``, ``t_s``,
    s), the firmware's ``_step_periods`` on bus time; ``advance`` without both times."""
    if prev_t_s is None or t_s is None:
        return advance
    budget = round((t_s - prev_t_s) / ENCODER_PERIOD_S) + RING // 2
    if budget <= advance:
        return advance
    return advance + (budget - advance) // RING * RING


def difference(a: FramePose, b: FramePose) -> dict[str, float]:
    """a - b: position (m), distance (m) and heading wrapped to (-pi, pi] (rad)."""
    dx, dy = a.x_m - b.x_m, a.y_m - b.y_m
    return {"dx_m": dx, "dy_m": dy, "dpos_m": math.hypot(dx, dy),
            "dheading_rad": wrap_angle(a.heading_rad - b.heading_rad)}


class FramePose(NamedTuple):
    """A pose at one encoder frame (``seq``: the how-many-th encoder frame the monitor heard,
    -1 when unknown); ``heading_rad`` is cumulative (unwrapped), ``pose_dict`` names both forms.
    A plain ``sim.pose.FramePose`` with the frame it is of: on-board, reference and truth samples
    are paired by ``seq``, never by time."""

    seq: int
    x_m: float
    y_m: float
    heading_rad: float


@dataclass
class ErrorStats:
    """A - B for a stream of pose pairs: the latest difference and the largest so far."""

    samples: int = 0
    latest: dict[str, float] = field(default_factory=dict)
    max_dpos_m: float = 0.0
    max_dheading_rad: float = 0.0

    def add(self, a: FramePose, b: FramePose) -> None:
        """Record ``a - b`` (position in m, heading wrapped to (-pi, pi] in rad)."""
        self.latest = difference(a, b)
        self.samples += 1
        self.max_dpos_m = max(self.max_dpos_m, self.latest["dpos_m"])
        self.max_dheading_rad = max(self.max_dheading_rad, abs(self.latest["dheading_rad"]))

    def as_dict(self) -> dict[str, Any] | None:
        """JSON form; None before the first sample."""
        if not self.samples:
            return None
        return {**self.latest, "max_dpos_m": self.max_dpos_m,
                "max_dheading_rad": self.max_dheading_rad, "samples": self.samples}


def pose_dict(pose: FramePose | None) -> dict[str, float] | None:
    """JSON form: ``x_m``, ``y_m``, ``heading_rad`` in (-pi, pi], ``heading_unwrapped_rad``."""
    if pose is None:
        return None
    return {"x_m": pose.x_m, "y_m": pose.y_m, **heading_fields(pose.heading_rad)}


def truth_heading(wrapped_rad: float, near: FramePose | None) -> float:
    """SIM_TRUTH's HEADING ([0, 2 pi) on the bus) made cumulative: the turn nearest ``near``
    (the reference at that encoder frame, else the previous truth), else wrapped (rad)."""
    return wrap_angle(wrapped_rad) if near is None else unwrap_near(wrapped_rad, near.heading_rad)
