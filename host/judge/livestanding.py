"""The live verdict's reasons beyond the latest sample (issue #11: the rig never shows OK while
the pose it reports is wrong; ``host.judge.monitor``).

The monitor's POSE WRONG judged the latest sample alone, so its state came back to OK while the
firmware's pose was still off:

* a lasting offset near the limit: the pose signals round to half an LSB, so a firmware X 1.2
  LSB off gives samples 0.7 to 1.7 LSB from the reference, and the state went POSE WRONG / OK
  with every other sample, ending OK on a right-looking one (51 episodes latched over 5 s of
  pmir on the circle, 0.17 mm off by a float64 dead reckoning of the test's own);
* a placement after a recorder gap or a stall (``host.judge.liveplace``) takes an offset within
  its allowance into the reference: the samples after it are right against it.

An odometry offset does not heal until the pose is set anew (a reboot, an applied set-pose:
``posewrongs.PoseWrongs.new_life``), so a POSE WRONG episode of the pose's current life keeps the
verdict POSE WRONG (``standing_why``). The live judge's own re-basings stay OK but say so
(``placed_why``): the pose is judged against a reference placed again where the firmware was,
within the allowance said (nothing judged across a gap without a bound), or started again at
the firmware's pose after an unseen controller restart.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from odocan.host.judge.livefit import pose_wrong
from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M

if TYPE_CHECKING:
    from odocan.host.judge.tracking import PoseTracker


def pose_wrong_why(tracker: PoseTracker) -> list[str]:
    """Why the verdict is POSE WRONG: the latest sample beyond the limit (after its loss and
    twin allowance, under the reference it was judged against: ``LiveAllowance.latest_m``),
    else ``standing_why``; [] when neither."""
    error = tracker.vs_reference.latest
    allowed_m = tracker.losses.latest_m()  # its own: for frames the firmware lost, and twins
    if error and pose_wrong(error["dpos_m"], error["dheading_rad"], allowed_m):
        plus = f" (allowed {allowed_m * 1e3:.4f} mm: lost frames, twins)" if allowed_m else ""
        return [f"on-board vs reference {error['dpos_m'] * 1e3:.4f} mm{plus}, "
                f"{error['dheading_rad'] * 1e3:.4f} mrad (limit one LSB: "
                f"{POSITION_LSB_M * 1e3:.1f} mm, {HEADING_LSB_RAD * 1e3:.4f} mrad)"]
    return standing_why(tracker)


def standing_why(tracker: PoseTracker) -> list[str]:
    """Why the verdict is POSE WRONG though the latest sample is within the limit: the episodes
    latched in the pose's current life and the latest sample; [] when there are none."""
    text = tracker.wrongs.standing_text()
    if not text:
        return _unsettled_why(tracker)
    latest = tracker.vs_reference.latest
    if not latest:
        return [text]
    allowed_m = tracker.losses.latest_m()
    if pose_wrong(latest["dpos_m"], latest["dheading_rad"], allowed_m):
        return [text]
    return [text, f"the latest sample ({latest['dpos_m'] * 1e3:.4f} mm, "
                  f"{latest['dheading_rad'] * 1e3:.4f} mrad) is within the limit, "
                  f"{_within_because(tracker)}: the offset stays until a set-pose or a reboot"]


def _unsettled_why(tracker: PoseTracker) -> list[str]:
    """A sample of the pose's life wrong with the allowance it has, not latched yet (its loss
    allowance is final at a later ODOM_STATUS page): the verdict does not wait for it."""
    wrong = tracker.wrongs.unsettled_wrong(tracker.allowance_m)
    if wrong is None:
        return []
    seq, t_s, beyond_m, dheading_rad = wrong
    return [f"a sample at {t_s:.2f} s (enc {seq}) was {beyond_m * 1e3:.4f} mm beyond its "
            f"allowance, {dheading_rad * 1e3:.4f} mrad off (one LSB: {POSITION_LSB_M * 1e3:.1f} "
            f"mm, {HEADING_LSB_RAD * 1e3:.4f} mrad); latched once no later page can allow it"]


def _within_because(tracker: PoseTracker) -> str:
    """Why a sample of a pose standing wrong is within the limit: the reference restarted at
    the firmware's pose (an unseen controller restart since the pose was last set anew whole:
    it adopted the offset) or placed again where the firmware was, else the rounding."""
    placements = tracker.placer.placements
    said = ["restarted at the firmware's pose after an unseen controller restart"
            ] if tracker.placer.dark.life_new_starts else []
    if placements.stalls or placements.gaps or placements.free:
        said.append("placed again where the firmware was")
    if tracker.adopted.life:  # a late-told reboot, a config or integrator change: liveadopted
        said.append("restarted at the firmware's own pose after "
                    + " and ".join(sorted({a.cause for a in tracker.adopted.life})))
    return "against a reference " + " and ".join(said) if said else "by the pose signals' rounding"


def placed_why(tracker: PoseTracker) -> list[str]:
    """The live judge's re-basings the reference judged against carries, said beside an OK
    ([] when none): its placements after a stall or a hold, after a gap of the encoder frames
    (bounded), after a gap without a bound; the new starts at the firmware's pose after an
    unseen controller restart since the pose was last set anew whole (a reboot, a set-pose of
    X, Y and HEADING: ``livedark.DarkRestarts.new_life``), not the watch's; its starts at the
    firmware's own pose after a late-told reboot, a config or an integrator change
    (``liveadopted.AdoptedStarts.why``), of the same life."""
    placements = tracker.placer.placements
    parts = []
    if placements.stalls:
        parts.append(f"{placements.stalls} stall{_s(placements.stalls)} (up to "
                     f"{placements.max_absorbed_m * 1e3:.4f} mm taken in, allowed "
                     f"{placements.allowance_m * 1e3:.4f} mm)")
    if placements.gaps:
        parts.append(f"{placements.gaps} gap{_s(placements.gaps)} of the encoder frames (up "
                     f"to {placements.max_gap_absorbed_m * 1e3:.4f} mm taken in, allowed "
                     f"{placements.gap_allowance_m * 1e3:.4f} mm)")
    if placements.free:
        parts.append(f"{placements.free} gap{_s(placements.free)} without a bound (an offset "
                     "there not judged)")
    why = ["judged against the reference placed again where the firmware was after "
           + " and ".join(parts)] if parts else []
    starts = tracker.placer.dark.life_new_starts  # since the pose was last set anew whole
    if starts:
        why.append(f"the reference restarted at the firmware's pose after {starts} unseen "
                   f"controller restart{_s(starts)} across a recorder hole (an offset it had "
                   "then not judged)")
    return why + tracker.adopted.why()  # its starts at the firmware's own pose (liveadopted)


def _s(count: int) -> str:
    return "" if count == 1 else "s"
