"""What a command needs to find in its frames before it analyses them, said plainly.

``analyze`` needs WHEEL_ENCODERS and the on-board pose, E2E-accepted. When a log (or a run)
has none of them, the message says what is actually wrong -- an empty log, a log of foreign
frames, frames that all fail their E2E check, a run whose frames the fault injector dropped or
corrupted -- instead of blaming the DBC (which is right: it is odocan's own).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TypeVar

import numpy as np

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.analysis import REQUIRED, AnalysisError
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import check_frames
from odocan.sim.exceptions import OdocanError

T = TypeVar("T")


class MissingFramesError(OdocanError):
    """The frames hold no usable frame of a message the analysis needs."""


def require_frames(frames: FrameArrays, source: str, cause: str = "") -> None:
    """Raise one line naming ``source`` when a message of ``REQUIRED`` has no frame in
    ``frames`` (``cause``: a likely reason, appended)."""
    db = default_plan()
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


def require_accepted(frames: FrameArrays, source: str, cause: str = "") -> None:
    """As ``require_frames``, then: at least one frame of each ``REQUIRED`` message passes its
    E2E check (with odocan's DBC, so a failure is the frames' fault, not the DBC's)."""
    require_frames(frames, source, cause)
    decoder = BulkDecoder(default_plan())
    _, accepted = check_frames(frames)
    for name in REQUIRED:
        index = decoder.select(frames, name)
        if not accepted[index].any():
            raise MissingFramesError(
                f"{source}: none of the {len(index)} {name} frames passes its E2E check "
                f"({cause or 'corrupted, or protected with other E2E data IDs'})"
            )


@contextmanager
def explained(frames: Callable[[], FrameArrays], source: str, cause: str = "") -> Iterator[None]:
    """Around ``analyze`` with odocan's DBC: when it gives up for want of frames, say why in
    terms of the input (``require_accepted``); any other refusal passes unchanged. Costs
    nothing when the analysis succeeds."""
    try:
        yield
    except AnalysisError:
        require_accepted(frames(), source, cause)
        raise
