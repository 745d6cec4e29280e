"""What a command needs to find in its frames before it analyses them, said plainly.

``analyze`` needs WHEEL_ENCODERS and the on-board pose. When a log (or a run) has none of
them, the message says what is actually wrong -- an empty log, a log of foreign frames, a run
whose frames the fault injector dropped -- instead of blaming the DBC.
"""

from __future__ import annotations

import numpy as np

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.analysis import REQUIRED
from odocan.host.protocol.decode import BulkDecoder
from odocan.sim import contract
from odocan.sim.exceptions import OdocanError


class MissingFramesError(OdocanError):
    """The frames hold none of a message the analysis needs."""


def require_frames(frames: FrameArrays, source: str, cause: str = "") -> None:
    """Raise one line naming ``source`` when a message of ``REQUIRED`` has no frame in
    ``frames`` (``cause``: a likely reason, appended)."""
    db = contract.database()
    decoder = BulkDecoder(db)
    missing = [name for name in REQUIRED if len(decoder.select(frames, name)) == 0]
    if not missing:
        return
    first = decoder.message(missing[0])
    what = f"no {missing[0]} frame (ID 0x{first.frame_id:03X}, {first.length} bytes)"
    if len(frames) == 0:
        detail = "no frame at all"
    else:
        ours = np.isin(frames.can_id, [m.frame_id for m in db.messages]).sum()
        detail = (
            f"{what} among its {len(frames)} frames"
            + (", none of them an odocan frame" if ours == 0 else "")
            + (f"; also none of {', '.join(missing[1:])}" if len(missing) > 1 else "")
        )
    raise MissingFramesError(f"{source}: {detail}{f' ({cause})' if cause else ''}")
