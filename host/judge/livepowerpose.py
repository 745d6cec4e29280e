"""The power-up pose judged against the life's start in the live judges (the monitor's and the
bridge's ``tracking.PoseTracker``), as ``analyze`` judges it (``host.judge.powerupjudged``,
issue #11: a PASS must never hide a wrong pose).

A pose half of E2E COUNTER 0 left out by the samples (``livehalves.HalfPairs``: the frame it
names has a twin, or is not heard yet from the latest frame) is kept up to ``POSE_LAP_S``; once a
new life starts at (0, 0, 0) on the frame it primed on (``livestart.Lives.finish_boot``), each
such half heard after the prime, less than ``POSE_LAP_S`` after it, naming the prime whichever
candidate (``powerupjudged.names_the_prime``: no frame of the life after the prime and heard
before the half has the prime's COUNTER), is judged against the start on what it carries (an X
half: X and HEADING, a Y half: Y), its error recorded as a lone half's (``liveresent``), at the
next pair settled or half left out (``livehalves``): after the reboot's withdrawal of the errors
from its first ticks on, which took it back when judged at the start."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from odocan.host.judge.livepose import FramePose
from odocan.host.judge.liveresent import record_error
from odocan.host.judge.livewindow import Counted, Half
from odocan.host.judge.powerupjudged import POSE_LAP_S, names_the_prime

if TYPE_CHECKING:
    from odocan.host.judge.tracking import PoseTracker

Prime = tuple[int, int, float]  # the frame a life primed on: seq, COUNTER, bus time (s)


class PowerUpPose:
    """The power-up pose halves left out, and the life's prime (module docstring)."""

    def __init__(self) -> None:
        self.pending: list[tuple[str, Half]] = []  # (name, half) of COUNTER 0, left out
        self.prime: Prime | None = None
        self._since: list[tuple[int, float]] = []  # the life's frames after it: COUNTER, t (s)
        self._last_seq = -1  # the latest of them (seq); later ones: the window's
        self._seen: set[tuple[str, float]] = set()  # (name, t s) of the halves kept

    def left_out(self, name: str, half: Half, tracker: PoseTracker) -> None:
        """Half ``name`` ("x" or "y") was left out by the samples: kept when of COUNTER 0."""
        if half.counter != 0 or (name, half.t_s) in self._seen:
            return  # (an X half both refused and left out: kept once)
        self._seen.add((name, half.t_s))
        self.pending = [(n, h) for n, h in self.pending if half.t_s - h.t_s < POSE_LAP_S]
        self._seen = {(n, t_s) for n, t_s in self._seen if half.t_s - t_s < POSE_LAP_S}
        self.pending.append((name, half))
        self.judge(tracker)

    def heard_x(self, signals: dict[str, Any], t_s: float, tracker: PoseTracker) -> None:
        """An ODOM_POSE_X of COUNTER 0 whose CRC holds (its decoded ``signals``), heard at bus
        time ``t_s`` whatever its E2E sequence: a power-up pose held back past its successors is
        refused by the check (kobuki 692: heard at 0.951 s, 150 ms late), kept as left out."""
        half = Half(-1, int(signals["ENC_COUNTER"]), int(signals["COUNTER"]), t_s,
                    float(signals["X"]), float(signals["HEADING"]))
        self.left_out("x", half, tracker)

    def booted(self, counts: list[Counted]) -> None:
        """A new life started at (0, 0, 0) on ``counts[0]`` (its frames heard so far)."""
        self.prime = (counts[0][0], counts[0][1], counts[0][6])
        self._since = [(c[1], c[6]) for c in counts[1:]]
        self._last_seq = counts[-1][0]  # judged at the next pair or half: after the reboot's
        # withdrawal of the errors from its first ticks on (``PoseTracker.withdraw_from``)

    def restarted(self) -> None:
        """The reference restarts (a reboot told, a set-pose, a config): no prime known."""
        self.prime = None

    def judge(self, tracker: PoseTracker) -> None:
        """Judge each pending half that is the prime's power-up pose (module docstring)."""
        prime = self.prime
        if prime is None or not self.pending or prime[0] in tracker.pairs.sampled:
            return
        raw = tracker.raw.at.get(prime[0])
        if raw is None:
            return
        ref = tracker.fit.correct(raw)
        rows = [row for row in tracker.window.rows if row[0] > self._last_seq]
        pending, self.pending = self.pending, []  # each decided now (a later frame: no prime)
        for name, half in pending:
            if not 0 < half.t_s - prime[2] < POSE_LAP_S:
                continue
            since = [c for c, t_s in self._since if t_s <= half.t_s] + [
                int(row[2]) for row in rows if float(row[3]) <= half.t_s]
            if names_the_prime(half.enc_counter, prime[1], since):
                pose = (FramePose(prime[0], half.value, ref.y_m, half.extra) if name == "x"
                        else FramePose(prime[0], ref.x_m, half.value, ref.heading_rad))
                record_error(tracker, prime[0], pose, ref, half.t_s)
