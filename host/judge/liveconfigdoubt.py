"""A config the bridge cannot tell, settled by the firmware's PROFILE page (issue #11: two
tools sending one PARAM under one COUNTER, ``host.judge.twosenders``).

The bridge follows its own ODOM_CONFIG frames when it sends them, not in the bus's order among
another tool's (``liveconfig.ConfigFollower(bus_order=False)``). When both tools sent one PARAM
with different values under one COUNTER, the firmware took the first on the bus and dropped the
second (E2E REPEATED: NACK REPEATED), and the ODOM_ACKs (COUNTER and PARAM only) do not say
whose came first: the APPLY's ACK leaves the judges with one of several robots
(``ConfigFollower.doubt``). Found on main: with the other tool's frame first, the bridge judged
the correct firmware with its own wheelbase: POSE WRONG (52 mm), TWIST WRONG, profile MISMATCH.

What the bridge does (``ConfigDoubt``): at the APPLY's ACK it takes its own values, as before,
says ``two senders`` (which PARAMs, both values), and holds its DISTANCE and speed judges
(suspended: they judge nothing of a robot not known). The firmware's next PROFILE page settles
it: the PROFILE_CRC (``profilepage.profile_crc``) of each candidate robot (every PARAM in doubt
with this bridge's value or the other's) is compared with the page's. The one that matches is
the judges' robot from there: when it is not the one taken, the POSE WRONG episodes and pending
samples since the APPLY are withdrawn (they were judged against a robot the firmware did not
run), with the largest errors and the loss allowance's maximum they raised
(``PoseTracker.withdraw_from``: before, the episodes only, and the fleet's end verdict, which
reads those maxima, FAILed the correct firmware at 3.0 mrad where the bridge's PASSed it; the
page comes a few samples after the APPLY, within the ``MARKS_KEPT`` taken back exactly), and
the reference restarts at the next on-board pose. A page no candidate matches settles
nothing: what was judged stands (a firmware that applied a robot neither tool sent stays
FAILed; its profile MISMATCH is said), and the DISTANCE and speed judges stay held.
"""

from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from odocan.host.judge.liveconfig import (
    INTEGRATORS,
    ConfigFollower,
    Judges,
    apply_config,
    staged_geometry,
)
from odocan.host.judge.livedistance import robot_of
from odocan.host.judge.profilepage import profile_crc

if TYPE_CHECKING:
    from odocan.host.judge.reference import Geometry

MAX_DOUBTED = 7  # ODOM_CONFIG's PARAMs: at most 2^7 candidate robots


@dataclass
class ConfigDoubt:
    """An applied config two senders left in doubt (module docstring)."""

    applied_s: float  # bus time of the APPLY's ACK (s)
    taken: dict[str, float]  # the staged set the judges took (this bridge's values in doubt)
    others: dict[str, float]  # PARAM in doubt: the other frame's value
    before: tuple[Geometry, int, str | None]  # the judges' robot before the APPLY

    def candidates(self) -> list[dict[str, float]]:
        """Every staged set the firmware may run, the one taken first."""
        params = sorted(self.others)[:MAX_DOUBTED]
        return [{**self.taken, **{p: self.others[p] for p, other in zip(params, pick,
                                                                         strict=True) if other}}
                for pick in itertools.product((False, True), repeat=len(params))]

    def crc(self, staged: dict[str, float], page_speed_mm_s: int) -> int:
        """The PROFILE_CRC of a firmware running ``staged`` over the robot before the APPLY
        (its speed bound the page's, unless staged)."""
        geometry, counter_bits, integrator = self.before
        g = staged_geometry(geometry, staged)
        if "MAX_WHEEL_SPEED" not in staged:
            g = dataclasses.replace(g, max_wheel_speed_mm_s=page_speed_mm_s)
        bits = int(staged.get("COUNTER_BITS", counter_bits))
        raw = staged.get("INTEGRATOR")
        name = INTEGRATORS[int(raw)] if raw is not None and 0 <= int(raw) < len(INTEGRATORS) \
            else integrator or "exact"
        return profile_crc(robot_of("", g, bits), name)


def doubt_config(judges: Judges, follower: ConfigFollower, before: tuple[Geometry, int,
                 str | None], t_s: float) -> ConfigDoubt | None:
    """After ``follow_config_ack`` applied a config at bus time ``t_s`` (s): its doubt when
    two senders left one (the DISTANCE and speed judges held, a ``two senders`` event), else
    None. ``before``: the judges' geometry, counter width and integrator before it."""
    if not follower.doubt:
        return None
    doubt = ConfigDoubt(t_s, dict(follower.applied), dict(follower.doubt), before)
    judges.distance.suspend()
    judges.twist.suspend()
    both = ", ".join(f"{p} {doubt.taken[p]:.6g} (this bridge's) or {v:.6g}"
                     for p, v in sorted(doubt.others.items()))
    judges.events.append({"t_s": t_s, "kind": "two senders", "detail": (
        f"two senders on ODOM_CONFIG: one COUNTER carried {both}: the firmware took the first "
        "on the bus, which the ACKs do not tell; judged with this bridge's until the PROFILE "
        "page settles it")})
    return doubt


def settle_config(judges: Judges, doubt: ConfigDoubt, s: dict[str, Any], t_s: float) -> None:
    """The firmware's first PROFILE page (decoded signals ``s``) after ``doubt``'s APPLY, at
    bus time ``t_s`` (s): the candidate it shows becomes the judges' robot (module docstring)."""
    crc = int(s["PROFILE_CRC"])
    speed_mm_s = round(float(s["MAX_WHEEL_SPEED"]) * 1000)
    found = next((c for c in doubt.candidates() if doubt.crc(c, speed_mm_s) == crc), None)
    if found is None:
        judges.events.append({"t_s": t_s, "kind": "two senders", "detail": (
            f"two senders on ODOM_CONFIG: the PROFILE page (0x{crc:08X}) shows neither "
            "tool's config: what was judged since the APPLY stands")})
        return
    if found != doubt.taken:
        judges.tracker.withdraw_from(doubt.applied_s)  # episodes, largest errors, allowance's
        apply_config(judges.tracker, found)
    geometry = judges.tracker.geometry
    counter_bits = int(found.get("COUNTER_BITS", doubt.before[1]))
    judges.distance.reconfigure(geometry, counter_bits)
    judges.twist.reconfigure(geometry, counter_bits)
    whose = "this bridge's" if found == doubt.taken else "the other tool's"
    runs = ", ".join(f"{p} {found[p]:.6g}" for p in sorted(doubt.others))
    withdrawn = "" if found == doubt.taken else (
        f"; the pose judged since the APPLY at {doubt.applied_s:.3f} s withdrawn, the "
        "reference restarts at the next on-board pose")
    judges.events.append({"t_s": t_s, "kind": "config", "detail": (
        f"two senders on ODOM_CONFIG settled by the PROFILE page (0x{crc:08X}): the firmware "
        f"runs {whose} {runs}{withdrawn}")})
