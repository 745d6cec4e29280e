"""The live judge never says OK while the firmware's last summary is too old to vouch for.

A firmware SIGCONTed after a stall sends its poses before its next ODOM_STATUS summary (the one
saying DEGRADED); the trial's screen showed "verdict OK" beside "firmware OK STALE age 3.0 s".
Here the lockstep rig's firmware runs (or stalls and resumes) and the host loses its summaries
for a while (``withheld``); the poses keep flowing and stay right, so only the summary's age
can keep the verdict from OK."""

from __future__ import annotations

import can

from odocan.sim.board import TICK_S
from tests.test_health_rig import STATUS, Watch, circle_rig

WHY_TICK = 650  # the verdict's reasons kept at 6.5 s


class SummaryLoss(Watch):
    """The judge as ``Watch``, but ODOM_STATUS frames between ``from_s`` and ``to_s`` never
    reach it (poses and the rest do)."""

    from_s: float = 0.0
    to_s: float = 0.0
    why: tuple[str, ...] | list[str] = ()

    def __call__(self, tick: int, frames: list[can.Message]) -> None:
        kept = [m for m in frames if not (m.arbitration_id == STATUS.frame_id
                                          and self.from_s <= m.timestamp < self.to_s)]
        super().__call__(tick, kept)
        if tick == WHY_TICK:
            self.why = self.monitor.health(self.verdicts[-1][0])["why"]


def run(from_s: float, to_s: float, halt_ticks: range = range(0)) -> SummaryLoss:
    with circle_rig() as rig:
        watch = SummaryLoss(rig)
        watch.from_s, watch.to_s = from_s, to_s
        rig.halted = lambda k: k in halt_ticks
        rig.run(to_s + 1.0)
        return watch


def verdicts(watch: SummaryLoss, t0: float, t1: float) -> set[str]:
    return {v for t, v in watch.verdicts if t0 <= t < t1}


def test_poses_without_a_fresh_summary_are_not_ok() -> None:
    watch = run(5.0, 7.0)
    assert verdicts(watch, 4.0, 5.0) == {"OK"}  # the run is judged OK before the loss
    # 10 x ODOM_STATUS's 100 ms after the last summary heard (a tick late at most): STALE
    assert verdicts(watch, 6.0 + 2 * TICK_S, 7.0) == {"STALE"}
    assert "no ODOM_STATUS summary" in watch.why[0]
    assert "it last said OK" in watch.why[0]
    assert verdicts(watch, 7.0 + 2 * TICK_S, 8.0) == {"OK"}  # a fresh summary: OK again


def test_a_resumed_firmware_is_not_ok_before_its_summary() -> None:
    # halted 5.0 .. 7.0 s (SIGSTOP), its first summaries after SIGCONT lost for 0.5 s
    watch = run(7.0, 7.5, halt_ticks=range(500, 700))
    assert "OK" not in verdicts(watch, 5.25, 7.5)
