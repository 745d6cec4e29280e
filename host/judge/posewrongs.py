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

An odometry offset does not heal: a pose once wrong stays off by what it took until the
firmware's pose is set anew, by a reboot (its power-up pose) or an applied set-pose
(``new_life``). The latest sample alone does not tell it: the pose signals' rounding (half an
LSB) puts the samples of a firmware 1.2 LSB off on either side of the one-LSB limit (a 0.6 LSB
offset too, now and then), and a placement after a gap or a stall takes an offset within its
allowance into the reference. So the episodes of the pose's current life are counted apart
(``standing``): while there is one, the live verdict is POSE WRONG whatever the latest sample
(``host.judge.monitor``), and ``as_dict`` carries them as ``this_life`` (``since_s``: the bus
time the life began, None for the watch's first; ``episodes``; ``worst``).
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

    def position_text(self) -> str:
        """``2.0494 mm off`` (``, 1.9 mm beyond its allowance`` when it had one)."""
        if self.dpos_mm - self.beyond_mm < 5e-5:  # no allowance: the figure once
            return f"{self.dpos_mm:.4f} mm off"
        return f"{self.dpos_mm:.4f} mm off ({self.beyond_mm:.4f} mm beyond its allowance)"

    def text(self, origin_s: float = 0.0) -> str:
        """What failed first (``worst_text``): ``position 2.0494 mm off at 6.01 s`` and/or
        ``heading 40.8814 mrad off at 6.01 s``, times from ``origin_s`` (bus time)."""
        return worst_text(self, self, origin_s)


def worst_text(position: Episode | None, heading: Episode | None, origin_s: float) -> str:
    """The worst position and the worst heading, each of its own episode, what failed only
    (both within their limits: the position's figure): ``position 7.5560 mm off at 12.34 s,
    heading 40.8814 mrad off at 3.02 s`` (seconds since ``origin_s``: the watch's first frame).
    Before, the worst episode by LSB gave its heading with its own position (0.41 mm where
    another episode was 7.56 mm off), bus times as epoch seconds and a 4-bit ``(enc 10)``."""
    said = []
    if position is not None and position.beyond_mm > POSITION_LSB_M * 1e3:
        said.append(f"position {position.position_text()} at {position.t_s - origin_s:.2f} s")
    if heading is not None and heading.dheading_mrad > HEADING_LSB_RAD * 1e3:
        said.append(f"heading {heading.dheading_mrad:.4f} mrad off at "
                    f"{heading.t_s - origin_s:.2f} s")
    if not said and position is not None:
        said.append(f"position {position.position_text()} at {position.t_s - origin_s:.2f} s")
    return ", ".join(said)


class PoseWrongs:
    """The samples waiting for their final allowance, and the episodes latched."""

    def __init__(self) -> None:
        self._pending: dict[int, tuple[float, float, float]] = {}  # frame: t_s, dpos, dheading
        self._suspects: set[int] = set()  # pending frames beyond the limit without allowance
        self.latest: deque[Episode] = deque(maxlen=MAX_EPISODES)
        self.count = 0  # episodes latched
        self.wrong_samples = 0
        self.worst: Episode | None = None
        self.worst_position: Episode | None = None  # the largest beyond its allowance
        self.worst_heading: Episode | None = None  # the largest heading error
        self.origin_s: float | None = None  # the watch's first frame (bus time): texts' zero
        self._open: Episode | None = None
        self.judged_until_s = math.inf  # two firmwares from then: no later sample is judged
        self.life_from_s = -math.inf  # bus time the pose's current life began (``new_life``)
        self.life_count = 0  # episodes with a wrong sample in it
        self.life_worst: Episode | None = None
        self._life_last: Episode | None = None  # the latest episode counted in it

    def new_life(self, t_s: float) -> None:
        """The firmware's pose was set anew at bus time ``t_s`` (a reboot, an applied
        set-pose): an offset taken before it is gone; the episodes before it stay latched
        (``count``, ``worst``), no longer ``standing``."""
        self.close()
        self.life_from_s, self.life_count = t_s, 0
        self.life_worst = self._life_last = None

    @property
    def standing(self) -> bool:
        """Whether the pose was wrong in its current life (module docstring)."""
        return self.life_count > 0

    def unjudgeable_from(self, t_s: float) -> None:
        """Two firmwares answered on one node ID from bus time ``t_s``: their pose frames cannot
        be told apart, so the samples from then are not judged, and the episodes latched from
        then are forgotten (the worst among those kept is the worst)."""
        self.judged_until_s = min(self.judged_until_s, t_s)
        self.withdraw_from(t_s)

    def withdraw_from(self, t_s: float) -> None:
        """The samples compared from bus time ``t_s`` on were judged against a robot the
        firmware did not run (``host.judge.liveconfigdoubt``): the episodes latched from then,
        and the samples pending from then, are forgotten."""
        self.close()
        self._pending = {seq: kept for seq, kept in self._pending.items() if kept[0] < t_s}
        self._suspects &= set(self._pending)
        gone = [e for e in self.latest if e.t_s >= t_s]
        self.count -= len(gone)
        self.wrong_samples -= sum(e.samples for e in gone)
        kept = [e for e in self.latest if e.t_s < t_s]
        self.latest = deque(kept, maxlen=MAX_EPISODES)
        if self.worst is not None and self.worst.t_s >= t_s:
            self.worst = max(kept, key=lambda e: e.size_lsb, default=None)
        if self.worst_position is not None and self.worst_position.t_s >= t_s:
            self.worst_position = max(kept, key=lambda e: e.beyond_mm, default=None)
        if self.worst_heading is not None and self.worst_heading.t_s >= t_s:
            self.worst_heading = max(kept, key=lambda e: e.dheading_mrad, default=None)
        self.life_count = max(0, self.life_count - sum(e.t_s >= self.life_from_s for e in gone))
        if self._life_last is not None and self._life_last.t_s >= t_s:
            self._life_last = None
        if self.life_worst is not None and self.life_worst.t_s >= t_s:
            self.life_worst = max((e for e in kept if e.t_s >= self.life_from_s),
                                  key=lambda e: e.size_lsb, default=None)
            self.life_count = self.life_count if self.life_worst is not None else 0

    def sample(self, seq: int, t_s: float, dpos_m: float, dheading_rad: float) -> None:
        """A sample of encoder frame ``seq`` (its ODOM_POSE_Y at bus time ``t_s``) was compared:
        ``dpos_m`` from the reference, ``dheading_rad``; judged once settled (``judged``)."""
        self._pending[seq] = (t_s, dpos_m, dheading_rad)
        if self.origin_s is None:  # no frame said before (a bridge): the first sample's
            self.origin_s = t_s
        if dpos_m > POSITION_LSB_M or abs(dheading_rad) > HEADING_LSB_RAD:
            self._suspects.add(seq)  # wrong unless a later page gives it an allowance

    def unsettled_wrong(self, allowance_m: Any) -> tuple[int, float, float, float] | None:
        """The worst sample of the pose's current life not settled yet that is wrong with the
        allowance it has now (``allowance_m``: frame -> m): (frame, t_s, dpos_m beyond it,
        dheading_rad); None when none. The latest sample may be right already; this one is
        latched once its allowance is final, unless a page gives it more."""
        worst, size = None, 0.0
        for seq in list(self._suspects):
            kept = self._pending.get(seq)
            if kept is None:
                self._suspects.discard(seq)
                continue
            t_s, dpos_m, dheading_rad = kept
            beyond_m = dpos_m - allowance_m(seq)
            lsb = max(beyond_m / POSITION_LSB_M, abs(dheading_rad) / HEADING_LSB_RAD)
            if self.life_from_s <= t_s < self.judged_until_s and lsb > 1.0 and lsb > size:
                worst, size = (seq, t_s, beyond_m, dheading_rad), lsb
        return worst

    def judged(self, settled: list[tuple[int, float]]) -> None:
        """Samples settled: (frame, position error beyond its final allowance, m), any order."""
        for seq, beyond_m in sorted(settled):
            kept = self._pending.pop(seq, None)
            self._suspects.discard(seq)
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
        self._worsts(episode)
        self._count_in_life(episode, t_s)

    def _worsts(self, episode: Episode) -> None:
        """``episode`` grew: the worst by LSB, by position and by heading follow it."""
        if self.worst is None or episode.size_lsb > self.worst.size_lsb:
            self.worst = episode
        if self.worst_position is None or episode.beyond_mm > self.worst_position.beyond_mm:
            self.worst_position = episode
        if self.worst_heading is None or episode.dheading_mrad > self.worst_heading.dheading_mrad:
            self.worst_heading = episode

    def _count_in_life(self, episode: Episode, t_s: float) -> None:
        """A wrong sample at bus time ``t_s`` of ``episode``: counted in the pose's current life
        unless it belongs to the life before (settled late)."""
        if t_s < self.life_from_s:
            return
        if episode is not self._life_last:
            self._life_last, self.life_count = episode, self.life_count + 1
        if self.life_worst is None or episode.size_lsb > self.life_worst.size_lsb:
            self.life_worst = episode

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
        self._worsts(episode)
        self._count_in_life(episode, t_s)  # the jump stands until the pose is set anew

    def close(self) -> None:
        """The open episode ends (a right sample, or a new reference)."""
        if self._open is not None:
            self._open.open = False
            self._open = None

    def finish(self, allowance_m: Any) -> None:
        """Judge the samples still waiting with the allowance they have now (``allowance_m``:
        frame -> m, the tracker's ``allowance_m``): the watch ends, no later page comes."""
        pending, self._pending, self._suspects = self._pending, {}, set()
        for seq in sorted(pending):
            self._judge(seq, pending[seq], pending[seq][1] - allowance_m(seq))

    def as_dict(self) -> dict[str, Any]:
        """``episodes`` (count), ``wrong_samples``, ``worst`` and ``latest`` (oldest first)
        episodes as dicts (None / [] when the pose was never wrong); ``this_life`` only while
        the pose is wrong in its current life (``standing``)."""
        wrongs = {"episodes": self.count, "wrong_samples": self.wrong_samples,
                  "worst": None if self.worst is None else asdict(self.worst),
                  "latest": [asdict(e) for e in self.latest]}
        if self.standing and self.life_worst is not None:
            since = None if self.life_from_s == -math.inf else self.life_from_s
            wrongs["this_life"] = {"since_s": since, "episodes": self.life_count,
                                   "worst": asdict(self.life_worst)}
        return wrongs

    def standing_text(self) -> str:
        """One line while ``standing``: ``the on-board pose was wrong in 3 episodes since its
        pose was set anew at 12.30 s, worst ...`` (``since the watch began`` in the first
        life); "" else."""
        if not self.standing or self.life_worst is None:
            return ""
        plural = "" if self.life_count == 1 else "s"
        since = ("since the watch began" if self.life_from_s == -math.inf
                 else f"since its pose was set anew at {self.life_from_s - self._origin():.2f} s")
        return (f"the on-board pose was wrong in {self.life_count} episode{plural} {since}, "
                f"worst {self.life_worst.text(self._origin())}")

    def summary(self) -> str:
        """One line: ``the on-board pose was wrong in 1 episode (12 samples), worst ...``; ""
        when it never was."""
        if self.worst is None:
            return ""
        plural = "" if self.count == 1 else "s"
        return (f"the on-board pose was wrong in {self.count} episode{plural} "
                f"({self.wrong_samples} samples), worst "
                + worst_text(self.worst_position, self.worst_heading, self._origin()))

    def _origin(self) -> float:
        """The texts' zero: the watch's first frame (``origin_s``), else bus time 0."""
        return 0.0 if self.origin_s is None else self.origin_s
