"""Where the streamed judge cuts a firmware life again (issue #11, #14.1): the applied set-poses
(``host.judge.setposes``) and configs (``host.judge.configs``) of a log fed chunk by chunk, the
same cuts as the whole log's, so that each piece is judged from the pose set or with the robot
applied, as ``host.judge.analysis`` judges it.

Carried: the accepted rows of ODOM_SET_POSE, ODOM_CONFIG, ODOM_AUTH and ODOM_ACK (a few per
command the host sent) at their log positions, and of the accepted encoder frames only those
the cuts read: the latest before and the first after each such row (``setposes.cuts_of`` and
``configs.cuts_of`` take the latest encoder frame before a row, or the first after an APPLY;
among these kept positions that is the same frame as among them all). ``cut_spans`` cuts the
firmware lives (``stream_lives.LifeSpan``) as ``setposes.cut_lives`` and ``configs.cut_configs``
cut the whole log's; ``first_integrator`` and ``latched_per_firmware`` are ``analysis``' for a
log cut so, each an extra pass over part of the log."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from odocan.host.io.frames import concat_frames, empty_frames
from odocan.host.io.logs import FrameArrays
from odocan.host.judge import configs, setposes
from odocan.host.judge.configs import ConfigCut
from odocan.host.judge.finalstate import latched_fields
from odocan.host.judge.samples import AnalysisError
from odocan.host.judge.setposes import SetPoseCut, optional_rows
from odocan.host.judge.stagedacks import ACK, ack_positions, ack_rows
from odocan.host.judge.statuslatch import StatusLatch
from odocan.host.judge.stream import StreamE2E
from odocan.host.judge.stream_facts import StreamFacts
from odocan.host.judge.stream_first import Frames
from odocan.host.judge.stream_lives import LifeSpan
from odocan.host.protocol.decode import BulkDecoder, DecodeError

if TYPE_CHECKING:  # a cantools Database or a plan of it (host.protocol.dbcplan)
    from odocan.host.protocol.dbcplan import DatabaseSpec

NAMES = tuple(dict.fromkeys((*setposes.COMMANDS, *configs.COMMANDS)))


@dataclass
class StreamCuts:
    """The rows of the module docstring over a log fed chunk by chunk (``accepted``: the
    chunk's E2E-accepted mask of the whole log's check, ``host.judge.stream.StreamE2E``)."""

    decoder: BulkDecoder
    _offset: int = 0
    _rows: dict[str, list[dict[str, np.ndarray]]] = field(default_factory=dict)
    _encoders: list[int] = field(default_factory=list)  # kept accepted encoder positions
    _last_encoder: int | None = None  # the latest accepted encoder frame's position so far
    _waiting: bool = False  # a row since it: the next accepted encoder frame is kept
    _acks: list[FrameArrays] = field(default_factory=list)  # every ODOM_ACK frame (``stagedacks``)
    _ack_positions: list[npt.NDArray[np.int64]] = field(default_factory=list)

    def feed(self, chunk: FrameArrays, accepted: npt.NDArray[np.bool_]) -> None:
        """Take the chunk's accepted command rows and the encoder frames around them."""
        positions: list[npt.NDArray[np.int64]] = []
        for name in NAMES:  # none of a name the DBC lacks
            rows = optional_rows(chunk, accepted, self.decoder, name)
            if len(rows["index"]):
                rows = dict(rows, index=rows["index"].astype(np.int64) + self._offset)
                self._rows.setdefault(name, []).append(rows)
                positions.append(rows["index"])
        acks = ack_positions(chunk, self.decoder)
        self._acks.append(chunk.select(acks))  # checked per firmware life at the end
        self._ack_positions.append(acks.astype(np.int64) + self._offset)
        encoders = self.decoder.select(chunk, "WHEEL_ENCODERS")
        encoders = encoders[accepted[encoders]].astype(np.int64) + self._offset
        self._keep_around(np.unique(np.concatenate(positions)) if positions else
                          np.zeros(0, dtype=np.int64), encoders)
        self._offset += len(chunk)

    def _keep_around(self, rows: npt.NDArray[np.int64],
                     encoders: npt.NDArray[np.int64]) -> None:
        """Keep the encoder frames just before and just after each of the chunk's ``rows``
        (log positions, sorted), carried across chunks."""
        if self._waiting and len(encoders):  # the first after an earlier chunk's last row
            self._encoders.append(int(encoders[0]))
            self._waiting = False
        if len(rows):
            at = np.searchsorted(encoders, rows)
            before = at > 0
            self._encoders += encoders[at[before] - 1].tolist()
            if not before.all() and self._last_encoder is not None:
                self._encoders.append(self._last_encoder)
            after = at < len(encoders)
            self._encoders += encoders[at[after]].tolist()
            self._waiting = not after.all()
        if len(encoders):
            self._last_encoder = int(encoders[-1])

    def _joined(self, reboots: list[int]) -> dict[str, dict[str, np.ndarray]]:
        """Each name's rows over the log (``optional_rows``' keys; the index empty if none);
        ODOM_ACK's E2E-checked afresh in each firmware life (``reboots``: where they start)."""
        joined: dict[str, dict[str, np.ndarray]] = {}
        for name in NAMES:
            parts = self._rows.get(name, [])
            joined[name] = ({key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
                            if parts else {"index": np.zeros(0, dtype=np.int64)})
        joined[ACK] = ack_rows(concat_frames(self._acks) if self._acks else empty_frames(),
                               np.concatenate([np.zeros(0, dtype=np.int64),
                                               *self._ack_positions]),
                               BulkDecoder(self.decoder.db), reboots)
        return joined

    def _encoder_positions(self) -> npt.NDArray[np.intp]:
        return np.unique(np.array(self._encoders, dtype=np.intp))

    def set_poses(self, firmware: Sequence[LifeSpan] = ()) -> list[SetPoseCut]:
        """``setposes.set_pose_cuts`` of the log fed (``firmware``: its firmware lives, at
        whose starts the staged fields are forgotten)."""
        rows = self._joined(reboots := [span.start for span in firmware[1:]])
        if not self._follows("ODOM_SET_POSE", rows):
            return []
        return setposes.cuts_of(rows, self._encoder_positions(), self.decoder, reboots)

    def configs(self, counter_bits: int, firmware: Sequence[LifeSpan] = ()) -> list[ConfigCut]:
        """``configs.config_cuts`` of the log fed (``counter_bits``: the log's robot's;
        ``firmware``: its firmware lives, as for ``set_poses``)."""
        rows = self._joined(reboots := [span.start for span in firmware[1:]])
        if not self._follows("ODOM_CONFIG", rows):
            return []
        return configs.cuts_of(rows, self._encoder_positions(), self.decoder, counter_bits,
                               reboots)

    def _follows(self, name: str, rows: dict[str, dict[str, np.ndarray]]) -> bool:
        """Whether there is anything to follow: the DBC has ``name`` and ODOM_ACK, and the log
        an accepted ACK (without one, no cut: the whole log's functions return early)."""
        try:
            self.decoder.message(name)
            self.decoder.message("ODOM_ACK")
        except (DecodeError, KeyError):
            return False
        return len(rows["ODOM_ACK"]["index"]) > 0


def cut_spans(spans: list[LifeSpan], set_poses: list[SetPoseCut],
              applied: list[ConfigCut]) -> list[LifeSpan]:
    """``spans`` cut at each set-pose, then at each applied config (``setposes.cut_lives``,
    ``configs.cut_configs``: a cut splits the life holding frames on both sides of it)."""
    for set_pose in set_poses:
        spans = _cut_once(spans, set_pose.position, set_pose.t_s, {"set_pose": set_pose})
    for config in applied:
        spans = _cut_once(spans, config.position, config.t_s, {"config": config})
    return spans


def _cut_once(spans: list[LifeSpan], position: int, t_s: float,
              why: dict[str, Any]) -> list[LifeSpan]:
    for k, span in enumerate(spans):
        if span.start < position < span.stop:
            head = dataclasses.replace(span, stop=position)
            tail = LifeSpan(position, span.stop, boot=False, t_s=t_s, **why)
            return [*spans[:k], head, tail, *spans[k + 1:]]
    return spans


def first_integrator(spans: list[LifeSpan], frames_of: Callable[[LifeSpan], Frames],
                     db: DatabaseSpec, integrator: str, source: str) -> str:
    """``analysis._first_integrator`` of the streamed log: the integrator ODOM_STATUS reports
    before the first applied config's APPLY (``integrator`` when given, without a config, or
    without a summary before it)."""
    cut = next((span.config for span in spans if span.config is not None), None)
    if cut is None or source != "ODOM_STATUS":
        return integrator
    try:
        return _facts(frames_of(LifeSpan(0, cut.apply_position, boot=False)), db).integrator(
            None)[0]
    except AnalysisError:  # no summary before it: the last one reported
        return integrator


def latched_per_firmware(firmware: list[LifeSpan], frames_of: Callable[[LifeSpan], Frames],
                         db: DatabaseSpec) -> dict[str, Any]:
    """``analysis._latched_per_firmware`` of the streamed log's firmware lives (``firmware``:
    before the cuts): each one's ``firmware_events``, its mask latched from its start (a cut
    does not clear the firmware's sticky bits), and the last one's ``firmware_final``."""
    events: list[dict[str, Any]] = []
    latch = StatusLatch()
    for k, span in enumerate(firmware):
        facts = _facts(frames_of(span), db)  # a reboot clears the firmware's state
        events += [dict(e, firmware_life=k) for e in facts.firmware_events]
        latch = facts.latch
    return latched_fields(events, latch)


def _facts(frames: Frames, db: DatabaseSpec) -> StreamFacts:
    """``StreamFacts`` of ``frames`` with their own E2E check."""
    e2e, facts = StreamE2E(db), StreamFacts(BulkDecoder(db))
    for chunk in frames():
        facts.feed(chunk, e2e.feed(chunk))
    return facts
