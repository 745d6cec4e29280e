"""ODOM_SET_POSE applied inside a log (issue #11): ``analyze`` cuts the log there and judges the
part after it as a new life whose reference starts at the pose set, as after a reboot it starts
at the power-up pose (``host.judge.reboots``).

The same rule as the live judge (``host.judge.livesetpose.SetPoseFollower``, run here over the
log's accepted ODOM_SET_POSE, ODOM_AUTH, ODOM_ACK and WHEEL_ENCODERS frames in bus order): a
field is staged when its ACK is heard; the APPLY takes effect after the latest accepted encoder
frame before it (or before its ODOM_AUTH), where the new life starts; it counts when its ACK
says ACK. When X, Y and HEADING were all staged the new life starts exactly at them
(``Life.set_pose``; the firmware's TURNS start again: the heading within [0, 2 pi)); when some
were not (the firmware kept its own values, e.g. a bare APPLY after a counter reset) its start
is fitted to its samples, as a log that starts mid-drive, and what it kept is checked at the
APPLY (``host.judge.setposekept``: a fit alone would follow a pose the firmware jumped to).
Either way its truth is compared in the new frame (re-based at the life's start,
``compare.life_origin``).

A reboot empties the firmware's staging (RAM): the follower forgets the fields staged before
it (``SetPoseFollower.forget`` at each firmware life's start, ``reboots.split_lives``), so a bare
APPLY after a reboot is judged as the firmware takes it, its own pose kept; the ODOM_ACKs are
E2E-checked afresh in each life (``stagedacks``: a new firmware's COUNTER restarts).

The streamed analysis cuts its lives at the same set-poses (``stream_cuts``, ``cuts_of`` of
the rows it gathers chunk by chunk)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.livesetpose import FIELDS, SetPoseFollower
from odocan.host.judge.reboots import Life, split_lives
from odocan.host.judge.stagedacks import acks_by_life
from odocan.host.protocol import busfacts
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e import check_frames

APPLY_FIELD = busfacts.APPLY_FIELD  # ODOM_SET_POSE FIELD / ODOM_ACK REQUEST_FIELD of APPLY
SET_POSE_REQUEST = 1  # ODOM_AUTH REQUEST naming ODOM_SET_POSE (the DBC's VAL_)


@dataclass(frozen=True)
class SetPoseCut:
    """An applied set-pose: the log position where the new life starts (the encoder frame it
    took effect after), the bus time of its ACK, the fields staged (m, rad)."""

    position: int
    t_s: float
    staged: dict[str, float]

    def start_pose(self) -> tuple[float, float, float] | None:
        """The exact start (x m, y m, heading rad in [0, 2 pi)) when every field was staged."""
        if not all(name in self.staged for name in FIELDS):
            return None
        return self.staged["X"], self.staged["Y"], self.staged["HEADING"]


def optional_rows(frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder,
                  name: str) -> dict[str, np.ndarray]:
    """The accepted decoded frames of ``name`` (none when the DBC lacks it; the set-pose and
    config cuts' ``samples.accepted_rows``, which refuses a log without them)."""
    try:
        rows = decoder.decode(frames, name)
    except (DecodeError, KeyError):
        return {"index": np.zeros(0, dtype=np.int64)}
    keep = accepted[rows["index"]]
    return {key: value[keep] for key, value in rows.items()}


def set_pose_cuts(frames: FrameArrays, decoder: BulkDecoder) -> list[SetPoseCut]:
    """The applied set-poses of the log, in bus order (module docstring). The E2E check runs
    only when an ODOM_ACK of an ODOM_SET_POSE APPLY is in the log at all."""
    try:
        raw = decoder.decode(frames, "ODOM_ACK")
        set_pose_id = decoder.message("ODOM_SET_POSE").frame_id
    except (DecodeError, KeyError):
        return []
    if not ((raw["REQUEST_ID"] == set_pose_id) & (raw["REQUEST_FIELD"] == APPLY_FIELD)).any():
        return []
    rows, encoders, reboots = followed_rows(frames, decoder, COMMANDS)
    return cuts_of(rows, encoders, decoder, reboots)


def followed_rows(frames: FrameArrays, decoder: BulkDecoder, names: Sequence[str]
                  ) -> tuple[dict[str, dict[str, np.ndarray]], npt.NDArray[np.intp], list[int]]:
    """What a command follower's ``cuts_of`` reads of a whole log (here and ``configs``): the
    accepted rows of the messages ``names`` (``optional_rows``; ODOM_ACK's E2E checked afresh in
    each firmware life, ``stagedacks``), the log positions of the accepted encoder frames, and
    the reboots (``reboot_positions``)."""
    _, accepted = check_frames(frames, decoder.db)
    encoders = decoder.select(frames, "WHEEL_ENCODERS")
    reboots = reboot_positions(frames, decoder)
    rows = {name: optional_rows(frames, accepted, decoder, name)
            for name in names if name != "ODOM_ACK"}
    rows["ODOM_ACK"] = acks_by_life(frames, decoder, reboots)
    return rows, encoders[accepted[encoders]], reboots


def reboot_positions(frames: FrameArrays, decoder: BulkDecoder) -> list[int]:
    """The log positions where the firmware lives after the first start (``split_lives``):
    where the followers forget what was staged (module docstring)."""
    return [int(life.index[0]) for life in split_lives(frames, decoder)[1:] if len(life.index)]


COMMANDS = ("ODOM_SET_POSE", "ODOM_AUTH", "ODOM_ACK")  # the accepted rows ``cuts_of`` follows


def cuts_of(rows: dict[str, dict[str, np.ndarray]], encoders: npt.NDArray[np.intp],
            decoder: BulkDecoder, reboots: Sequence[int] = ()) -> list[SetPoseCut]:
    """``set_pose_cuts`` from the log's accepted rows of ``COMMANDS`` (``optional_rows``, their
    index the log position) and the log positions of its accepted encoder frames (``encoders``:
    at least the latest before each of those rows; the streamed judge keeps no more);
    ``reboots``: where the firmware lives after the first start (``reboot_positions``)."""
    commands, auths, acks = (rows[name] for name in COMMANDS)
    mine = acks["REQUEST_ID"] == decoder.message("ODOM_SET_POSE").frame_id
    steps: list[tuple[int, str, int]] = (
        [(int(i), "boot", -1) for i in reboots]
        + [(int(i), "cmd", k) for k, i in enumerate(commands["index"].tolist())]
        + [(int(i), "auth", k) for k, i in enumerate(auths["index"].tolist())
           if int(auths["REQUEST"][k]) == SET_POSE_REQUEST]
        + [(int(i), "ack", k) for k, i in enumerate(acks["index"].tolist()) if mine[k]])
    return _follow(sorted(steps), commands, acks, encoders, decoder)


def _follow(steps: list[tuple[int, str, int]], commands: dict[str, np.ndarray],
            acks: dict[str, np.ndarray], encoders: npt.NDArray[np.intp],
            decoder: BulkDecoder) -> list[SetPoseCut]:
    """``SetPoseFollower`` over the frames in bus order; the encoder 'seq' it notes is the log
    position of the latest accepted encoder frame."""
    follower, cuts = SetPoseFollower(), []
    message = decoder.message("ODOM_SET_POSE")
    scales = {name: float(message.get_signal_by_name(name).scale) for name in FIELDS}
    for position, kind, k in steps:
        before = int(np.searchsorted(encoders, position)) - 1
        latest = int(encoders[before]) if before >= 0 else -1
        if kind == "cmd":
            field_raw = int(commands["FIELD"][k])
            field = "APPLY" if field_raw == APPLY_FIELD else FIELDS[field_raw] \
                if field_raw < len(FIELDS) else str(field_raw)
            value = None
            if field in FIELDS and field in commands:  # raw: scaled by the DBC's factor
                value = float(commands[field][k]) * scales[field]
            follower.on_frame(int(commands["COUNTER"][k]), field, value, latest)
        elif kind == "auth":
            follower.on_auth(latest)
        elif kind == "boot":  # the firmware's staging was in its RAM
            follower.forget()
        else:
            applied = follower.on_ack(int(acks["REQUEST_COUNTER"][k]), int(acks["RESULT"][k]) == 0)
            if applied is not None and applied[0] >= 0:
                cuts.append(SetPoseCut(applied[0], float(acks["timestamp_s"][k]), applied[1]))
    return cuts


def cut_lives(lives: list[Life], cuts: list[SetPoseCut]) -> list[Life]:
    """``lives`` cut again at each set-pose: the part from the cut's position on is a new life
    (``Life.set_pose``), judged from the pose set, its truth re-based."""
    for cut in cuts:
        for k, life in enumerate(lives):
            inside = life.index >= cut.position
            if 0 < int(np.count_nonzero(inside)) < len(life.index):
                head = replace(life, index=life.index[~inside])
                tail = Life(life.index[inside], boot=False, t_s=cut.t_s, set_pose=cut)
                lives = [*lives[:k], head, tail, *lives[k + 1:]]
                break
    return lives
