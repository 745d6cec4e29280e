"""The live judge's raw reference (``host.judge.tracking``): the float64 ``ReferenceOdometry``
before the start fit corrects it, its pose at each of the latest encoder frames (the frame a
sample names is compared at), and the firmware's step gate it is stepped through. Owned by the
tracker (``PoseTracker.raw``); started by ``livestart``, placed again by ``liveplacing``, taken
from a twin by ``livechoice``."""

from __future__ import annotations

from odocan.host.judge.livepose import FramePose, RestartLog, StepGate
from odocan.host.judge.livewindow import ENC_WINDOW, Counted
from odocan.host.judge.reference import Geometry, ReferenceOdometry


class RawReference:
    """``odometry`` (None until started, again after a restart), ``at`` (its pose at the latest
    encoder frames, by seq), ``gate`` (``StepGate``: the frames' steps the firmware takes) and
    ``started`` (the pose it started at, on the frame it primed on: ``livereprime`` replays a
    re-prime after a stall before the life's first sample from it). ``blind``: its poses are
    kept nowhere, so nothing is compared with it (``liverobot``: a robot the firmware does not
    run; the samples are still numbered, settled and published, without a reference)."""

    __slots__ = ("at", "blind", "gate", "odometry", "started")

    def __init__(self, gate: StepGate) -> None:
        self.odometry: ReferenceOdometry | None = None
        self.at: dict[int, FramePose] = {}
        self.gate = gate
        self.started: FramePose | None = None
        self.blind = False

    def start(self, odometry: ReferenceOdometry, geometry: Geometry, counter_bits: int,
              told: RestartLog) -> None:
        """Start at ``odometry`` (its pose the start's), nothing kept, a new gate."""
        self.odometry, self.at, self.started = odometry, {}, None
        self.gate = StepGate(geometry, counter_bits, told)

    def stop(self) -> None:
        """No reference until the next start (a restart)."""
        self.odometry, self.at, self.started = None, {}, None

    def step(self, ref: ReferenceOdometry, frame: Counted) -> tuple[int, int] | None:
        """Step ``ref`` (the started odometry) by ``frame`` as the gate takes it (None: not
        stepped; a first frame primes) and keep its pose at the frame; returns the step."""
        step = self.gate.step(frame)
        if step is not None:
            ref.step_deltas(step[0], step[1])  # (by position: no tuple unpacked per frame)
        if self.blind:  # nothing compared (liverobot)
            return step
        seq = frame[0]  # ``ref.heading_rad`` in line (per encoder frame): ``_heading_at``'s sum;
        # the NamedTuple made by ``tuple.__new__`` (its ``__new__`` is a Python lambda)
        self.at[seq] = tuple.__new__(FramePose, (seq, ref.x_m, ref.y_m, ref._heading0_rad
                                                 + ref._k_right * ref._cum_right
                                                 - ref._k_left * ref._cum_left))
        self.at.pop(seq - ENC_WINDOW, None)
        return step

    def forget(self, before: int) -> None:
        """Drop the poses kept at the encoder frames before ``before`` (seq)."""
        self.at = {seq: ref for seq, ref in self.at.items() if seq >= before}
