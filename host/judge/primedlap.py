"""A life's first pose made by a firmware that primed on a frame after the life's first, its
first tick integrating a backlog (issue #11: a FAIL must never blame a correct firmware).

``lapfirst`` tells the frame a life's first pose names from the life's start: (0, 0, 0) at its
first encoder frame. A firmware whose process opened its bus while the robot's frames went on,
its first tick ~0.7 s later, primes on the oldest frame its mailbox kept, not on the first the
log holds: the log's first life when the recorder started before the firmware did. Captured
(``backlog_first_tick_c2.log``, pmir): the firmware primed on encoder frame 24 of the log, its
first tick integrated its full 32-slot mailbox and named frame 55 by ENC_COUNTER 8 (its first
pose X 32.2 mm, Y -11.6 mm, heading -0.6786 rad, DISTANCE 35 mm: 0.02 mm and 0.01 mrad from
frames 24..55 in float64), the judges paired it with frame 71, the newest of COUNTER 8: 81.1 mm,
418 mrad and DISTANCE 21.5 mm off, a FAIL of a correct firmware in every judge.

The rule, when no older lap fits from the life's start: the frames the pose may name are
``lapfirst.lap_candidates`` (the named frame and each a COUNTER lap before it) within
``LAPS_BACK`` laps; the frame the firmware may have primed on is each of the ``PRIME_SPAN``
frames before a candidate (two 32-slot mailboxes: a tick integrates at most what its mailbox
held). The pose at a candidate from (0, 0, 0) at a prime is ``reference.integrate`` over the
counts between; a candidate is taken when the pose fits it from some prime
(``lapfirst.fits``: X, Y, heading, DISTANCE each within 2 LSBs) and fits no other candidate from
any prime, and it is not the newest (the plain name stands then). A pose 10 mm off fits no
candidate from any prime (its X alone is 50 LSBs from every one): the plain name stands and it
FAILs as before; a wrong pose that fits an older lap from some prime by chance has all four
quantities right there to 2 LSBs, what a correct firmware primed there says.
"""

from __future__ import annotations

import numpy as np

from odocan.host.judge.reference import Geometry, integrate, wrap_delta
from odocan.host.judge.samples import WIRE_COUNTER_BITS, Encoders
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP
from odocan.sim.robot import RobotProfile

PRIME_SPAN = 64  # frames before a candidate the firmware may have primed on (2 mailboxes)
LAPS_BACK = 8  # COUNTER laps before the named frame a backlog may reach (128 frames)


def primed_candidate(said: tuple[float, float, float, float | None], enc: Encoders,
                     cands: list[int], robot: RobotProfile, integrator: str,
                     heading_only: bool = False) -> int | None:
    """The position in ``cands`` (``lapfirst.lap_candidates``, newest first) of the one older
    lap ``said`` (X, Y, heading, DISTANCE) fits from (0, 0, 0) at some prime before it; None
    when none, several, or the newest fits (module docstring). ``heading_only``: X and Y not
    compared (the streamed judge's look-ahead: no integrator changes heading and DISTANCE)."""
    from odocan.host.judge.lapfirst import Said, fits  # lapfirst imports this module

    near = [c for c in cands if c >= cands[0] - LAPS_BACK * ENC_COUNTER_LAP]
    hits: set[int] = set()
    bits = min(robot.counter_bits, WIRE_COUNTER_BITS)
    geometry = Geometry.of(robot)
    d_left = wrap_delta(np.diff(enc.left[: near[0] + 1]), bits)
    d_right = wrap_delta(np.diff(enc.right[: near[0] + 1]), bits)
    for prime in range(max(0, near[-1] - PRIME_SPAN), near[0]):
        path = integrate(d_left[prime: near[0]], d_right[prime: near[0]], geometry, integrator)
        for pos, c in enumerate(near):
            if not prime < c <= prime + PRIME_SPAN:
                continue
            at = c - prime - 1
            ref = Said(float(path.x_m[at]), float(path.y_m[at]), float(path.heading_rad[at]),
                       float(path.distance_m[at]))
            pose = Said(*said)
            if heading_only:
                pose = pose._replace(x_m=ref.x_m, y_m=ref.y_m)
            if fits(pose, ref):
                hits.add(pos)
    if len(hits) != 1 or 0 in hits:
        return None
    return hits.pop()
