"""Live alignment of what a robot's bus says: the on-board pose against a float64 reference and
the ground truth, each paired at the very encoder frame it names (ENC_COUNTER), never by time.

Used by ``odocan monitor`` and the MQTT bridge. The offline, bulk version of the same rule is
``host.analysis``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, NamedTuple

from odocan.firmware.ecu import ENCODER_PERIOD_US, MAX_WHEEL_SPEED_MM_S, RESYNC_FRAMES
from odocan.host.judge.reference import Geometry, ReferenceOdometry, wrap_delta
from odocan.host.protocol.pose import PosePairer, heading_fields, unwrap_near
from odocan.sim.pose import wrap_angle

WIRE_COUNTER_BITS = 24  # LEFT_COUNT / RIGHT_COUNT carry the low 24 bits
_RING = 16  # one slot per E2E COUNTER value of WHEEL_ENCODERS
SILENCE_FRAMES = 8  # encoder frames heard without a pose: the firmware was stalled
BACKLOG_FRAMES = 6_000  # encoder frames kept while waiting for the integrator (60 s at 100 Hz)
_TURN = 2.0 * math.pi


class StepGate:
    """The firmware's plausibility rule on the reference's steps (firmware/ecu.py, the same as
    ``host.judge.analysis``): a frame beyond ``MAX_WHEEL_SPEED_MM_S`` over the periods its COUNTER
    advanced since the last accepted one is refused; ``RESYNC_FRAMES`` refused frames plausible
    among themselves are a counter restart: one step from the first of them, never the jump."""

    def __init__(self, geometry: Geometry, counter_bits: int) -> None:
        travel_m = MAX_WHEEL_SPEED_MM_S * 1e-3 * ENCODER_PERIOD_US * 1e-6
        self.bound = (math.ceil(travel_m / geometry.m_per_count_left) + 1,
                      math.ceil(travel_m / geometry.m_per_count_right) + 1)
        self.bits = counter_bits
        self.prev: tuple[int, int, int] | None = None  # counter, left, right of the last accepted
        self._refused: list[tuple[int, int, int]] = []
        self.counter_restarts = 0

    def _delta(self, a: tuple[int, int, int], b: tuple[int, int, int]) -> tuple[int, int]:
        return wrap_delta(b[1] - a[1], self.bits), wrap_delta(b[2] - a[2], self.bits)

    def _plausible(self, a: tuple[int, int, int], b: tuple[int, int, int]) -> bool:
        periods = ((b[0] - a[0]) % _RING) or _RING
        d = self._delta(a, b)
        return abs(d[0]) <= periods * self.bound[0] and abs(d[1]) <= periods * self.bound[1]

    def step(self, counter: int, left: int, right: int) -> tuple[int, int] | None:
        """The count step to integrate for this frame; None when it primes or is refused."""
        frame = (counter, left, right)
        prev, self.prev = self.prev, frame
        if prev is None:
            return None
        if self._plausible(prev, frame):
            self._refused = []
            return self._delta(prev, frame)
        self.prev = prev  # refused: the base stays
        consistent = bool(self._refused) and self._plausible(self._refused[-1], frame)
        self._refused = [*self._refused, frame] if consistent else [frame]
        if len(self._refused) < RESYNC_FRAMES:
            return None
        first, self._refused, self.prev = self._refused[0], [], frame
        self.counter_restarts += 1
        return self._delta(first, frame)


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


class PoseTracker:
    """On-board pose vs the float64 reference (aligned by ENC_COUNTER) and vs SIM_TRUTH.

    The reference starts at the first on-board pose heard, primed with the counts of the
    encoder frame that pose names and stepped with every accepted WHEEL_ENCODERS frame after it.
    When the integrator is not known yet (``integrator`` None: the one ODOM_STATUS reports), the
    poses and encoder frames heard meanwhile are kept (up to ``BACKLOG_FRAMES``) and compared
    once it is, so the monitor (which waits for ODOM_STATUS) and the bridge (told the integrator)
    start at the same pose and judge the same samples as ``analyze``. FramePose halves are paired by
    ``host.protocol.pose.PosePairer``, the one pairing. The reference starts again when
    ODOM_STATUS reports another integrator. At power-up the first pose is exactly (0, 0, 0), the
    start ``analyze`` uses; mid-drive the start inherits the pose signals' rounding (0.1 mm,
    2 pi/65536 rad; ``analyze`` fits it instead), so the difference stays within about one LSB.
    """

    def __init__(
        self, geometry: Geometry, counter_bits: int, integrator: str | None = None
    ) -> None:
        """``counter_bits``: the robot's hardware counter width (16 wraps within the 24 on the
        bus); ``integrator`` None: the one ODOM_STATUS reports."""
        self.geometry = geometry
        self.counter_bits = min(counter_bits, WIRE_COUNTER_BITS)
        self.forced = integrator is not None
        self.integrator = integrator
        self.enc_seq = -1
        self._frames_since_pose = 0
        self.stalls = 0  # firmware silences after which the reference restarted
        self._counts: list[tuple[int, int, int] | None] = [None] * _RING  # seq, left, right
        self._refs: list[FramePose | None] = [None] * _RING
        self._ref: ReferenceOdometry | None = None
        self._gate = StepGate(geometry, self.counter_bits)
        self._pairer = PosePairer()
        self._pending: FramePose | None = None  # the first pose, heard before the integrator
        self._backlog_counts: list[tuple[int, int, int, int]] = []  # seq, counter, left, right
        self._backlog_poses: list[FramePose] = []
        self._truth_parts: dict[int, tuple[int, float]] = {}
        self._last_pair: tuple[FramePose, FramePose] | None = None  # on-board, reference
        # (ENC_COUNTER, encoder frame named or -1, frames heard then) of the last X and Y half
        self._last_x: tuple[int, int, int] | None = None
        self._last_y: tuple[int, int, int] | None = None
        self._last_compared = -1  # the encoder frame of the last sample compared
        self._place_at_next = False  # after a stall or a held pose: place the position again
        self.pose: FramePose | None = None
        self.reference: FramePose | None = None
        self.truth: FramePose | None = None
        self.reference_starts = 0
        self.vs_reference = ErrorStats()
        self.vs_truth = ErrorStats()
        self.reference_vs_truth = ErrorStats()

    def on_encoders(self, counter: int, left: int, right: int) -> None:
        """An accepted WHEEL_ENCODERS frame (raw 24-bit counts)."""
        self.enc_seq += 1
        self._frames_since_pose += 1
        self._counts[counter] = (self.enc_seq, left, right)
        ref = self._ref
        if ref is not None:
            step = self._gate.step(counter, left, right)
            if step is not None:
                ref.step_deltas(*step)
            self._refs[counter] = FramePose(self.enc_seq, ref.x_m, ref.y_m, ref.heading_rad)
        elif self._pending is not None:
            self._backlog_counts.append((self.enc_seq, counter, left, right))
            if len(self._backlog_counts) > BACKLOG_FRAMES:  # too long: start at a later pose
                self._drop_backlog()

    def on_integrator(self, name: str) -> None:
        """ODOM_STATUS reports the firmware's integrator; a change restarts the reference."""
        if self.forced or name == self.integrator:
            return
        first = self.integrator is None
        self.integrator = name
        if first and self._pending is not None:  # judge what was heard while waiting
            self._start_reference(self._pending, self._backlog_counts, self._backlog_poses)
            self._drop_backlog()
        else:
            self.restart_reference()

    def restart_reference(self) -> None:
        """Start the reference again at the next on-board pose (after a set-pose or config)."""
        self._ref = None
        self._last_compared = -1
        self._place_at_next = False
        self._refs = [None] * _RING
        self._drop_backlog()

    def _drop_backlog(self) -> None:
        self._pending = None
        self._backlog_counts = []
        self._backlog_poses = []

    def set_geometry(self, geometry: Geometry, counter_bits: int) -> None:
        """New robot parameters (a config command); the reference restarts at the next pose."""
        self.geometry = geometry
        self.counter_bits = min(counter_bits, WIRE_COUNTER_BITS)
        self.restart_reference()

    def on_pose_x(self, enc_counter: int, x_m: float, heading_rad: float) -> None:
        """ODOM_POSE_X (X in m, HEADING in rad within the turn)."""
        seq = self._resolve(self._last_x, enc_counter)
        self._last_x = (enc_counter, seq, self.enc_seq)
        self._pairer.on_x({"ENC_COUNTER": enc_counter, "X": x_m, "HEADING": heading_rad}, seq)

    def _resolve(self, last: tuple[int, int, int] | None, enc_counter: int) -> int:
        """The encoder frame (seq) a pose half names, -1 when unknown. A half repeating the
        ENC_COUNTER of the previous half of its kind, fewer than ``SILENCE_FRAMES`` frames later,
        names what that one named (E2E refuses a repeated COUNTER: the firmware held on one frame,
        e.g. after a late and a lost frame, while the bus carried a new frame with the same
        COUNTER; ``host.judge.analysis._held``)."""
        if last is not None and last[0] == enc_counter and self.enc_seq - last[2] < SILENCE_FRAMES:
            return last[1]
        named = self._named(self._counts[enc_counter])
        return int(named[0]) if named is not None else -1

    def on_pose_y(
        self, enc_counter: int, y_m: float, turns: int
    ) -> tuple[FramePose, FramePose | None] | None:
        """ODOM_POSE_Y: with the ODOM_POSE_X of the same encoder frame, one on-board sample.

        Returns (on-board pose, reference at that encoder frame or None), None when unpaired.
        """
        silent, self._frames_since_pose = self._frames_since_pose >= SILENCE_FRAMES, 0
        if silent and self._ref is not None:
            # The firmware was stalled: this pose names a backlog frame ENC_COUNTER cannot
            # resolve, and it took the frames it missed as one step: the reference's position
            # is placed again at the next pose (its heading, a function of the counts, goes on).
            self.stalls += 1
            self._place_at_next = True
            self._pairer.on_y({"ENC_COUNTER": enc_counter, "Y": y_m, "TURNS": turns})
            return None
        seq = self._resolve(self._last_y, enc_counter)
        self._last_y = (enc_counter, seq, self.enc_seq)
        paired = self._pairer.on_y({"ENC_COUNTER": enc_counter, "Y": y_m, "TURNS": turns}, seq)
        if paired is None:
            return None
        pose = self.pose = FramePose(seq, paired.x_m, paired.y_m, paired.heading_rad)
        named = self._named(self._counts[enc_counter])
        if named is not None and named[0] != seq:
            named = None  # the ring moved on: the frame this pose names is a held one
        held = 0 <= self._last_compared <= seq - SILENCE_FRAMES
        if self._ref is not None and held and not self._place_at_next:
            # The firmware held its pose that long, then took the frames since as one step,
            # which a fine reference cannot follow on a curve: placed again, as after a stall.
            self.stalls += 1
            self._place_at_next = True
        if self._ref is None and named is not None:
            if self._pending is None:
                self._pending = pose
                self._backlog_counts = sorted(
                    (c[0], i, c[1], c[2]) for i, c in enumerate(self._counts)
                    if c is not None and c[0] >= seq
                )
            if self.integrator is None:
                self._backlog_poses.append(pose)
                return pose, None
            self._start_reference(self._pending, self._backlog_counts, [])
            self._drop_backlog()
        ref = self._named(self._refs[enc_counter])
        if ref is None or seq < 0 or ref.seq != seq:
            return pose, None
        if self._place_at_next:
            ref = self._place(pose, ref)
        self.reference = ref
        self._last_pair = (pose, ref)
        self._last_compared = seq
        self.vs_reference.add(pose, ref)
        return pose, ref

    def _place(self, pose: FramePose, ref: FramePose) -> FramePose:
        """Move the reference's position (now and at the frames heard since ``ref``) by
        ``pose - ref``: it starts again where the firmware is, within the pose's rounding (so
        within about 1.4 LSB after), while its heading goes on exact. Returns the moved ``ref``."""
        assert self._ref is not None
        dx, dy = pose.x_m - ref.x_m, pose.y_m - ref.y_m
        self._ref.x_m += dx
        self._ref.y_m += dy
        self._refs = [r if r is None or r.seq < ref.seq else r._replace(x_m=r.x_m + dx,
                                                                         y_m=r.y_m + dy)
                      for r in self._refs]
        self._place_at_next = False
        return ref._replace(x_m=ref.x_m + dx, y_m=ref.y_m + dy)

    def on_truth(
        self, part: int, enc_counter: int, value: float
    ) -> tuple[FramePose, FramePose | None] | None:
        """A SIM_TRUTH part (0 X m, 1 Y m, 2 HEADING rad); three of one encoder frame: a sample.

        Returns (truth, reference at that encoder frame or None) once the sample is complete.
        """
        self._truth_parts[part] = (enc_counter, value)
        parts = self._truth_parts
        if len(parts) < 3 or len({p[0] for p in parts.values()}) != 1:
            return None
        self._truth_parts = {}
        ref = self._named(self._refs[enc_counter])
        truth = self.truth = FramePose(
            ref.seq if ref else -1, parts[0][1], parts[1][1], self._truth_heading(parts[2][1], ref)
        )
        if ref is None:
            return truth, None
        self.reference_vs_truth.add(ref, truth)
        if self._last_pair is not None:  # the on-board pose carried to this frame
            pose, at = self._last_pair
            estimate = FramePose(
                ref.seq, pose.x_m - at.x_m + ref.x_m, pose.y_m - at.y_m + ref.y_m,
                pose.heading_rad - at.heading_rad + ref.heading_rad,
            )
            self.vs_truth.add(estimate, truth)
        return truth, ref

    @property
    def counter_restarts(self) -> int:
        """Counter restarts the current reference re-primed on (as the firmware does)."""
        return self._gate.counter_restarts

    def _truth_heading(self, wrapped_rad: float, ref: FramePose | None) -> float:
        """SIM_TRUTH's HEADING ([0, 2 pi) on the bus) made cumulative: the turn nearest the
        reference at that encoder frame, else nearest the previous truth (rad)."""
        if ref is not None:
            return unwrap_near(wrapped_rad, ref.heading_rad)
        if self.truth is not None:
            return unwrap_near(wrapped_rad, self.truth.heading_rad)
        return wrap_angle(wrapped_rad)

    def _named(self, entry: Any) -> Any:
        """A ring entry if it is one of the last 8 encoder frames (not one 16 frames older)."""
        if entry is None or self.enc_seq - entry[0] >= _RING // 2:
            return None
        return entry

    def _start_reference(
        self, pose: FramePose, counts: list[tuple[int, int, int, int]], poses: list[FramePose]
    ) -> None:
        """Start the reference at ``pose``, primed on the first of ``counts`` (seq, counter,
        left, right: the encoder frame ``pose`` names and those after it), catch up, and compare
        the ``poses`` heard meanwhile."""
        assert self.integrator is not None
        ref = self._ref = ReferenceOdometry(
            self.geometry, self.integrator, self.counter_bits,
            x_m=pose.x_m, y_m=pose.y_m, heading_rad=pose.heading_rad,
        )
        self.reference_starts += 1
        self._refs = [None] * _RING
        self._gate = StepGate(self.geometry, self.counter_bits)
        at_seq: dict[int, FramePose] = {}
        for seq, counter, left, right in counts:
            step = self._gate.step(counter, left, right)  # the first primes: stays at pose
            if step is not None:
                ref.step_deltas(*step)
            sample = FramePose(seq, ref.x_m, ref.y_m, ref.heading_rad)
            at_seq[seq] = self._refs[counter] = sample
        for heard in poses:
            at = at_seq.get(heard.seq)
            if at is not None:
                self.reference = at
                self._last_pair = (heard, at)
                self._last_compared = heard.seq
                self.vs_reference.add(heard, at)

    def snapshot(self) -> dict[str, Any]:
        """``pose``, ``reference``, ``truth`` (None until known) and ``error``."""
        return {
            "pose": pose_dict(self.pose),
            "reference": {**(pose_dict(self.reference) or {}), "integrator": self.integrator,
                          "starts": self.reference_starts,
                          "counter_restarts": self.counter_restarts, "stalls": self.stalls},
            "truth": pose_dict(self.truth),
            "error": {
                "pose_vs_reference": self.vs_reference.as_dict(),
                "pose_vs_truth": self.vs_truth.as_dict(),
                "reference_vs_truth": self.reference_vs_truth.as_dict(),
            },
        }


def pose_dict(pose: FramePose | None) -> dict[str, float] | None:
    """JSON form: ``x_m``, ``y_m``, ``heading_rad`` in (-pi, pi], ``heading_unwrapped_rad``."""
    if pose is None:
        return None
    return {"x_m": pose.x_m, "y_m": pose.y_m, **heading_fields(pose.heading_rad)}
