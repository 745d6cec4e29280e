"""Pass 1 of the streamed judge over one life (``host.judge.stream_analysis``): E2E, the
encoder sequence, the samples after stalls and holds, truth, twist, facts, the spans where the
firmware lost encoder frames the log holds, the firmware's E2E pages, and what makes a life one
the stream cannot judge as the whole log (``FirstPass.refuse``)."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from odocan.host.io.frames import concat_frames
from odocan.host.io.logs import FrameArrays
from odocan.host.judge.earlytwins import EarlyTwinScan
from odocan.host.judge.gapfill import crc_holds
from odocan.host.judge.gapseen import PageEvidence
from odocan.host.judge.lapfirst import REFUSAL as LAPPED
from odocan.host.judge.lapfirst import lagged
from odocan.host.judge.samples import (
    REQUIRED,
    AnalysisError,
    Poses,
    queued_frames,
    twinned_encoder_frames,
)
from odocan.host.judge.stalls import silent
from odocan.host.judge.stream import StreamE2E, StreamEncoders, StreamPoses
from odocan.host.judge.stream_facts import StreamFacts
from odocan.host.judge.stream_late import REFUSAL as LATE
from odocan.host.judge.stream_late import StreamLate
from odocan.host.judge.stream_losses import StreamLosses
from odocan.host.judge.stream_primed import PowerUpPrefix
from odocan.host.judge.stream_refusal import AHEAD, UNSETTLED, NamesAhead, NotStreamable
from odocan.host.judge.stream_stalls import StreamStalls
from odocan.host.judge.stream_truth import StreamTruth
from odocan.host.judge.stream_twist import StreamTwist
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP
from odocan.host.protocol.decode import BulkDecoder
from odocan.sim.robot import RobotProfile

if TYPE_CHECKING:  # a cantools Database or a plan of it (host.protocol.dbcplan)
    from odocan.host.protocol.dbcplan import DatabaseSpec

@dataclass
class FirstSilence:
    """``stalls.first_after_stall`` chunk by chunk: the firmware's last ODOM_STATUS before its
    first pose and the encoder frames logged from it up to that pose (a stream that finds the
    silence refuses: ``FirstPass.refuse``)."""

    talked_s: float | None = None
    heard: int = 0
    decided: bool = False
    stalled: bool = False

    def feed(self, status_s: np.ndarray, enc_s: np.ndarray, pose_s: np.ndarray,
             cycle_s: float | None) -> None:
        """A chunk's accepted ODOM_STATUS, encoder frame and ODOM_POSE_Y bus times."""
        if self.decided:
            return
        cut = float(pose_s.min()) if len(pose_s) else math.inf
        before = status_s[status_s < cut]
        if len(before):
            self.talked_s, self.heard = float(before.max()), 0
        if self.talked_s is not None:
            self.heard += int(np.count_nonzero((enc_s >= self.talked_s) & (enc_s < cut)))
        if len(pose_s):
            self.decided = True
            self.stalled = (cycle_s is not None and self.talked_s is not None and bool(
                silent(np.array([cut - self.talked_s]), np.array([self.heard]), cycle_s)[0]))


Frames = Callable[[], Iterable[FrameArrays]]  # a life's frames, from its first, each call
QUEUED_MESSAGES = ("WHEEL_ENCODERS", "ODOM_POSE_X", "ODOM_POSE_Y", "ODOM_TWIST")


class FirstPass:
    """Pass 1 over a life (``stream_analysis``'s module docstring)."""

    def __init__(self, db: DatabaseSpec, robot: RobotProfile) -> None:
        self.decoder, self.robot = BulkDecoder(db), robot
        self.e2e = StreamE2E(db)
        self.numbering = StreamEncoders(self.decoder)
        self.poses = StreamPoses(self.decoder)
        self.truth = StreamTruth(self.decoder)
        self.twist = StreamTwist(self.decoder, robot)
        self.facts = StreamFacts(self.decoder)
        self.losses = StreamLosses(self.decoder)
        self.pages = PageEvidence(self.decoder)  # what the firmware took (gapseen)
        self.late = StreamLate(self.decoder)  # a pose or twist frame named where sent
        self.queued = False  # frames of a periodic sender let out in a burst (queued_frames)
        self.twins = False  # an encoder frame with a twin (samples.twinned_encoder_frames)
        self.early = EarlyTwinScan(self.decoder)  # or an early twin (earlytwins)
        self.resent_kept = False  # a sample kept whose resend differs (StreamPoses.resent)
        self._last_enc: dict[str, np.ndarray] | None = None  # the last accepted encoder row
        self._last_t: dict[str, float] = {}  # per such message, its last accepted frame's time
        self.stalls: StreamStalls | None = None
        self.rows = dict.fromkeys(REQUIRED, 0)  # decoded frames of the required messages
        self.accepted = dict.fromkeys(REQUIRED, 0)  # and those E2E accepts
        self.samples = self.kept = self.truths = self.encoders = 0
        self.head = self.tail = poses_of({})
        self.t_first_s = 0.0
        self.before_first = FirstSilence()  # a stall before the first pose (stalls)
        self.prefix = PowerUpPrefix(self.decoder)  # a power-up primed late (stream_primed)
        self.first_sent_s = math.inf  # the first on-board sample's bus time (its least)

    def feed(self, chunk: FrameArrays) -> None:
        if self.e2e.counts == {} and len(chunk):
            self.t_first_s = float(chunk.timestamp_s[0])
        accepted = self.e2e.feed(chunk)
        self.prefix.feed(chunk, accepted)
        for name in REQUIRED:
            index = self.decoder.select(chunk, name)
            self.rows[name] += len(index)
            self.accepted[name] += int(np.count_nonzero(accepted[index]))
        enc = self.numbering.feed(chunk, accepted)
        self.encoders += len(enc.index)
        self.stalls = self.stalls or StreamStalls(enc.cycle_s,
                                                  named_again=self.poses.named_again)
        samples, sent = self.poses.feed(chunk, accepted, enc)
        self.first_sent_s = min(self.first_sent_s, float(np.min(sent, initial=math.inf)))
        watermark = min(float(chunk.timestamp_s[-1]), self.poses.open_sent_s())
        pose_y = self.decoder.select(chunk, "ODOM_POSE_Y")
        pose_t = chunk.timestamp_s[pose_y[accepted[pose_y] | crc_holds(  # stalls.pose_sent_times
            chunk, self.decoder, pose_y, "ODOM_POSE_Y")]]
        status = self.decoder.select(chunk, "ODOM_STATUS")
        self.before_first.feed(chunk.timestamp_s[status[accepted[status]]], enc.timestamp_s,
                               pose_t, enc.cycle_s)
        self._kept(self.stalls.feed(samples, sent, enc.timestamp_s, watermark, pose_t), samples)
        self.truths += len(self.truth.feed(chunk, accepted, enc)[0]["enc"])
        self.twist.feed(chunk, accepted, enc)
        self.facts.feed(chunk, accepted)
        self.losses.feed(chunk, accepted, enc)
        self.pages.feed(chunk, enc)
        self.late.feed(chunk, accepted)
        if enc.cycle_s is not None:
            self._bursts(chunk, accepted, enc.cycle_s)
        self._twins(chunk, accepted)

    def _twins(self, chunk: FrameArrays, accepted: np.ndarray) -> None:
        """Whether an accepted encoder frame has a twin (``samples.twinned_encoder_frames``,
        over the chunk and the last accepted encoder frame before it)."""
        rows = self.decoder.decode(chunk, "WHEEL_ENCODERS")
        keep = accepted[rows["index"]]
        if self._last_enc is not None:
            rows = {k: np.concatenate((self._last_enc[k], v)) for k, v in rows.items()}
            keep = np.concatenate(([True], keep))
        if keep.any():
            last = int(np.flatnonzero(keep)[-1])
            self._last_enc = {k: v[last:last + 1] for k, v in rows.items()}
        self.twins = self.twins or bool(
            twinned_encoder_frames(chunk, rows, keep, self.decoder).any())
        self.twins = self.early.feed(chunk, accepted) or self.twins

    def _bursts(self, chunk: FrameArrays, accepted: np.ndarray, cycle_s: float) -> None:
        """Whether a message ``samples.queued_frames`` looks at (encoder frames, poses, twist)
        has two accepted frames closer than it allows, in log order (a superset of every
        pair it can find: a pair in time order has one at least as close in log order)."""
        for name in QUEUED_MESSAGES:
            index = self.decoder.select(chunk, name)
            t = chunk.timestamp_s[index[accepted[index]]]
            if len(t) == 0:
                continue
            if name in self._last_t:
                t = np.concatenate(([self._last_t[name]], t))
            self.queued = self.queued or bool(queued_frames(t, cycle_s).any())
            self._last_t[name] = float(t[-1])

    def finish(self) -> None:
        if self.stalls is None:
            return
        samples, sent = self.poses.finish()
        self.first_sent_s = min(self.first_sent_s, float(np.min(sent, initial=math.inf)))
        self._kept(self.stalls.feed(samples, sent, np.zeros(0), np.inf), samples)
        self._kept(self.stalls.finish(), {"enc": np.zeros(0)})
        self.truths += len(self.truth.finish()[0]["enc"])

    def _kept(self, kept: dict[str, np.ndarray], fed: dict[str, np.ndarray]) -> None:
        self.samples += len(fed["enc"])
        self.resent_kept |= -1 in self.poses.resent or bool(  # a sample kept, a resend differs
            np.isin(kept["enc"], sorted(self.poses.resent)).any())
        if len(kept["enc"]):
            if self.kept == 0:
                self.head = poses_of({k: v[:1] for k, v in kept.items()})
            self.tail = poses_of({k: v[-1:] for k, v in kept.items()})
            self.kept += len(kept["enc"])

    def refuse(self) -> None:
        """``NotStreamable`` when the life is one the stream cannot judge as the whole log."""
        if self.twins:  # the stream's encoder frames carry no twins (samples.encoder_frames)
            raise NotStreamable("two encoder frames of one COUNTER (a forger or a second sender)")
        if self.stalls is not None and not self.stalls.exact:
            raise NotStreamable("the log's frame times go back around a silence of the firmware")
        if not self.losses.exact:  # a summary stamped before an earlier encoder frame
            raise NotStreamable("the log's status times go back against its encoder frames")
        if not self.e2e.exact:  # verdicts the whole life's evidence settles (stream_e2e)
            raise NotStreamable(UNSETTLED)
        self._refuse_lapped()
        if self.queued:  # samples._queued pairs them by a median over the whole life
            raise NotStreamable("frames let out in a burst after a busy bus (queued pairing)")
        if self.before_first.stalled:  # the whole log's after_stalls leaves its first pose out
            raise NotStreamable("the firmware stalled before its first pose")
        if self.resent_kept:  # judged whole (host.judge.resent), as the sample is out already
            raise NotStreamable("a resent pose differs from the first naming its encoder frame")
        if self.poses.lone or self.poses.ahead:  # judged by the whole log's judge: on what it
            # carries (lonehalves), at the frames it may name (aheadnamed)
            raise (NotStreamable("a pose half whose partner was lost (a lone half)")
                   if self.poses.lone else NamesAhead(AHEAD))
        if self.late.found:  # the stream names it where heard (stream_late)
            raise NotStreamable(LATE)

    def _refuse_lapped(self) -> None:
        """``NotStreamable`` when the life's first pose may name a frame a COUNTER lap before
        the newest of its ENC_COUNTER (``lapfirst.lagged``): the whole log's judge tells it."""
        if len(self.head.enc) and int(self.head.enc[0]) < ENC_COUNTER_LAP:
            return  # its first sample's frame has no lap before it in the life
        if self.prefix.complete and lagged(concat_frames([c for c, _ in self.prefix.chunks]),
                                           np.concatenate([a for _, a in self.prefix.chunks]),
                                           self.decoder, self.robot):
            raise NotStreamable(LAPPED)

    @property
    def breaks(self) -> np.ndarray:
        return self.stalls.breaks if self.stalls is not None else np.zeros(0, dtype=np.int64)

    def check(self) -> None:
        """``analysis._analyze_life``'s errors, in its order: the required messages missing
        or all refused, no on-board sample."""
        for name in REQUIRED:
            if self.accepted[name] == 0:
                message = self.decoder.message(name)
                if self.rows[name] == 0:
                    raise AnalysisError(
                        f"no {name} frame (ID 0x{message.frame_id:03X}, {message.length} bytes)"
                        " in the log: the DBC does not match the log")
                raise AnalysisError(f"none of the {self.rows[name]} {name} frames passes its "
                                    "E2E check: the DBC does not match the log")
        if self.samples == 0:
            raise AnalysisError("no ODOM_POSE_X/ODOM_POSE_Y pair names an encoder frame of the "
                                "log: nothing to compare")


def first_pass(frames: Frames, db: DatabaseSpec,
                robot: RobotProfile) -> FirstPass:
    first = FirstPass(db, robot)
    for chunk in frames():
        first.feed(chunk)
    first.finish()
    return first


def poses_of(columns: dict[str, np.ndarray]) -> Poses:
    empty_i, empty_f = np.zeros(0, dtype=np.int64), np.zeros(0)
    return Poses(columns.get("enc", empty_i), columns.get("x_m", empty_f),
                 columns.get("y_m", empty_f), columns.get("heading_rad", empty_f),
                 columns.get("heading_raw", empty_i))
