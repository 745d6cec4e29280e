"""The live judge's POSE WRONG episodes, latched (issue #11): the live verdict does not forget.

The monitor's verdict (``host.judge.monitor``) judges the latest on-board sample. After a
firmware jump the judge may later place its reference again where the firmware is (a recorder
gap or a stall: ``host.judge.liveplace``, within a bounded allowance), and from then on the
latest sample is right again: the verdict went back to OK while ``analyze`` of the same log
still FAILs (it judges every sample). As the firmware latches its own errors
(``host.judge.statuslatch``: ``firmware_events``, ``latched_errors``), the host latches every
*episode* of samples judged wrong: consecutive samples beyond ``analyze``'s limit, one LSB of
position after the loss and twin allowance, or one LSB of heading (``livefit.pose_wrong``).

A sample is judged here once its allowance is final (``livelosses.LiveAllowance.settle``: no
later ODOM_STATUS page can give its frame more), so a correct firmware that lost frames the
bus carried is never latched wrong on the way; ``finish`` judges the samples still waiting with
the allowance they have (the end of a watch: no later page comes). Then the episodes say the
firmware was wrong exactly when ``analyze`` of the same frames would
(``max_position_error_beyond_allowance_m`` or ``max_heading_error_rad`` over one LSB).

Each episode: ``t_s`` (bus time of the ODOM_POSE_Y of its first wrong sample, s), ``end_t_s``
(of its last), ``enc_seq`` (the encoder frame its first wrong sample names, counted from the
first WHEEL_ENCODERS frame heard, as the bridge's ``pose`` and ``error`` messages number it),
``samples``, and its size: ``dpos_mm`` (the largest position error), ``beyond_mm`` (the
largest beyond its allowance), ``dheading_mrad`` (the largest heading error), ``open`` (its
latest sample was wrong). The state is bounded: ``MAX_EPISODES`` latest, the worst and the
counts kept for ever.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import asdict, dataclass
from typing import Any

from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M

MAX_EPISODES = 8  # the latest episodes kept (all are counted; the worst is kept too)


@dataclass
class Episode:
    """Consecutive samples judged wrong (module docstring: the fields)."""

    t_s: float
    end_t_s: float
    enc_seq: int
    samples: int = 0
    dpos_mm: float = 0.0
    beyond_mm: float = 0.0
    dheading_mrad: float = 0.0
    open: bool = True

    def add(self, t_s: float, dpos_m: float, beyond_m: float, dheading_rad: float) -> None:
        """One more wrong sample (bus time s; errors in m and rad)."""
        self.end_t_s, self.samples = t_s, self.samples + 1
        self.dpos_mm = max(self.dpos_mm, 1e3 * dpos_m)
        self.beyond_mm = max(self.beyond_mm, 1e3 * beyond_m)
        self.dheading_mrad = max(self.dheading_mrad, 1e3 * abs(dheading_rad))

    @property
    def size_lsb(self) -> float:
        """How far beyond the limit, in LSB of whichever is worse (position or heading)."""
        return max(1e-3 * self.beyond_mm / POSITION_LSB_M,
                   1e-3 * self.dheading_mrad / HEADING_LSB_RAD)

    def text(self) -> str:
        """``2.0494 mm (beyond allowance 2.0494 mm), 0.0479 mrad at 6.01 s (enc 598)``."""
        return (f"{self.dpos_mm:.4f} mm (beyond allowance {self.beyond_mm:.4f} mm), "
                f"{self.dheading_mrad:.4f} mrad at {self.t_s:.2f} s (enc {self.enc_seq})")


class PoseWrongs:
    """The samples waiting for their final allowance, and the episodes latched."""

    def __init__(self) -> None:
        self._pending: dict[int, tuple[float, float, float]] = {}  # frame: t_s, dpos, dheading
        self.latest: deque[Episode] = deque(maxlen=MAX_EPISODES)
        self.count = 0  # episodes latched
        self.wrong_samples = 0
        self.worst: Episode | None = None
        self._open: Episode | None = None
        self.judged_until_s = math.inf  # two firmwares from then: no later sample is judged

    def unjudgeable_from(self, t_s: float) -> None:
        """Two firmwares answered on one node ID from bus time ``t_s``: their pose frames cannot
        be told apart, so the samples from then are not judged, and the episodes latched from
        then are forgotten (the worst among those kept is the worst)."""
        self.judged_until_s = min(self.judged_until_s, t_s)
        self.close()
        gone = [e for e in self.latest if e.t_s >= t_s]
        self.count -= len(gone)
        self.wrong_samples -= sum(e.samples for e in gone)
        kept = [e for e in self.latest if e.t_s < t_s]
        self.latest = deque(kept, maxlen=MAX_EPISODES)
        if self.worst is not None and self.worst.t_s >= t_s:
            self.worst = max(kept, key=lambda e: e.size_lsb, default=None)

    def sample(self, seq: int, t_s: float, dpos_m: float, dheading_rad: float) -> None:
        """A sample of encoder frame ``seq`` (its ODOM_POSE_Y at bus time ``t_s``) was compared:
        ``dpos_m`` from the reference, ``dheading_rad``; judged once settled (``judged``)."""
        self._pending[seq] = (t_s, dpos_m, dheading_rad)

    def judged(self, settled: list[tuple[int, float]]) -> None:
        """Samples settled: (frame, position error beyond its final allowance, m), any order."""
        for seq, beyond_m in sorted(settled):
            kept = self._pending.pop(seq, None)
            if kept is not None:
                self._judge(seq, kept, beyond_m)

    def _judge(self, seq: int, kept: tuple[float, float, float], beyond_m: float) -> None:
        t_s, dpos_m, dheading_rad = kept
        if t_s >= self.judged_until_s:
            return
        if beyond_m <= POSITION_LSB_M and abs(dheading_rad) <= HEADING_LSB_RAD:
            self.close()
            return
        episode = self._open
        if episode is None:
            episode = self._open = Episode(t_s, t_s, seq)
            self.count += 1
            self.latest.append(episode)
        episode.add(t_s, dpos_m, beyond_m, dheading_rad)
        self.wrong_samples += 1
        if self.worst is None or episode.size_lsb > self.worst.size_lsb:
            self.worst = episode

    def jumped(self, seq: int, t_s: float, dpos_m: float, dheading_rad: float) -> None:
        """A set-pose APPLY moved what it kept (``host.judge.livekept``: ``analyze``'s check of
        the samples around it): an episode of its own, at the first sample after it (frame
        ``seq``, its ODOM_POSE_Y at ``t_s``), sized by the jump (m, rad)."""
        if t_s >= self.judged_until_s:
            return
        self.close()
        episode = Episode(t_s, t_s, seq, open=False)
        episode.add(t_s, dpos_m, dpos_m, dheading_rad)
        self.count, self.wrong_samples = self.count + 1, self.wrong_samples + 1
        self.latest.append(episode)
        if self.worst is None or episode.size_lsb > self.worst.size_lsb:
            self.worst = episode

    def close(self) -> None:
        """The open episode ends (a right sample, or a new reference)."""
        if self._open is not None:
            self._open.open = False
            self._open = None

    def finish(self, allowance_m: Any) -> None:
        """Judge the samples still waiting with the allowance they have now (``allowance_m``:
        frame -> m, the tracker's ``allowance_m``): the watch ends, no later page comes."""
        pending, self._pending = self._pending, {}
        for seq in sorted(pending):
            self._judge(seq, pending[seq], pending[seq][1] - allowance_m(seq))

    def as_dict(self) -> dict[str, Any]:
        """``episodes`` (count), ``wrong_samples``, ``worst`` and ``latest`` (oldest first)
        episodes as dicts (None / [] when the pose was never wrong)."""
        return {"episodes": self.count, "wrong_samples": self.wrong_samples,
                "worst": None if self.worst is None else asdict(self.worst),
                "latest": [asdict(e) for e in self.latest]}

    def summary(self) -> str:
        """One line: ``the on-board pose was wrong in 1 episode (12 samples), worst ...``; ""
        when it never was."""
        if self.worst is None:
            return ""
        plural = "" if self.count == 1 else "s"
        return (f"the on-board pose was wrong in {self.count} episode{plural} "
                f"({self.wrong_samples} samples), worst {self.worst.text()}")
