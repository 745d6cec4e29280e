"""DISTANCE samples naming a frame the reference says the firmware refused (issue #11, rule 5: a
FAIL never blames a correct firmware), for ``distance.DistanceJudge``.

An ODOM_TWIST names by ENC_COUNTER the last encoder frame its firmware took. Where the
reference's state machine (``reference_path.firmware_steps``) refuses a run of frames (each
beyond the plausibility bound from the last one it took, or a counter restart's run before its
re-prime), a firmware that followed the reference took none of them and names none: a sample
naming one proves the firmware took a chain the host's E2E did not (its twin, or a frame the
host refused or never heard), and its DISTANCE there is not the reference's path at the frame
(nor at the last frame the reference took). The steps the firmware made into it the reference
makes at the run's end, merged: the sample reads above the reference by up to that step, and
the samples after the run agree again. Judged, it pinned the interval of the allowed offsets
high, and the next sample, back on the reference, emptied it.

Found under ``--faults delay=0.5:150,drop=0.1`` on figure8 (a 150 ms delay is 15 periods: a
late frame's COUNTER is one ahead of the on-time one's): pmir seed 7, 10 s, the host took a late
frame of COUNTER 9 where the firmware took the on-time one, refused the next two frames as 57
counts in a period from it, and a twist naming the first (COUNTER 10, 7.93 s) read 67.4 mm above
the reference; kobuki seed 2, 10 s, the firmware re-primed on a frame the host never accepted,
one before the reference's, and named a frame of the reference's restart run 11.9 mm above it.
Such a sample is left out (its information is the firmware's chain, not the reference's); the
samples before and after it still pin the value, so a DISTANCE off by 10 mm from some time on
still FAILs. The live DISTANCE judge (``livedistance``) applies it too: a twist naming a frame
its own step gate refused is left out (pmir figure8 seed 7, 20 s: the live judges FAILed the
correct firmware by 66.66 mm there, after their naming of late twists was made ``analyze``'s,
``livelatetwists``; tests/test_f8_delay_distance.py)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from odocan.host.judge.reference_path import Steps


def refused_frames(steps: Steps, n_frames: int) -> npt.NDArray[np.bool_]:
    """Per frame of ``steps``' window (0: its first, never refused; ``n_frames`` frames): whether
    the reference refused it inside a run (``Steps.taken_before``: the frame taken again after
    a run, and the one taken before it; a run open at the end reaches ``n_frames``)."""
    out = np.zeros(n_frames, dtype=np.bool_)
    for k, before in steps.taken_before.items():
        out[before + 1 : min(k, n_frames)] = True
    return out
