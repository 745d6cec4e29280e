"""A power-up primed late, judged by the streamed judge as the whole log's judge does it (issue
#11; ``host.judge.primedrange``): from each frame 0 .. min(k, n) its first count page and first
pose allow, in bounded memory.

The whole log's judge reads ``k`` (``powerup.primed_after``: the first count page and the
summaries before it) and ``n`` (``powerup.first_pose_named``: the first pose and the encoder
frames before it) from the life's first frames, and each candidate's start pose from the motion
over frames 0 .. p (``primedon.start_pose_primed_on``). All of that lies in the log's first
seconds: ``PowerUpPrefix`` holds the life's frames (and the stream's exact E2E verdicts on
them) up to the chunk that holds both the first accepted count page and the first accepted
ODOM_POSE_X, at most ``MAX_PREFIX_FRAMES``. The event is then the whole judge's, and the life
is streamed again from each candidate's start (``primedon.judged_from_each``: the first that
passes, else all). Before, the stream refused such a life and the CLI read the log whole
(about 2.7 MB of memory per MB of candump log: an hour's drive took 200 MB and more).

A prefix that outgrew ``MAX_PREFIX_FRAMES`` before both were heard (a firmware silent for
minutes after its power-up) is still refused (``NotStreamable``, ``TOO_LONG``)."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from typing import Any

import numpy as np
import numpy.typing as npt

from odocan.host.io.frames import concat_frames
from odocan.host.io.logs import FrameArrays
from odocan.host.judge.analysis import Analysis
from odocan.host.judge.primedon import judged_from_each
from odocan.host.judge.primedrange import primed_range_event
from odocan.host.judge.samples import ENC_E2E_PAGE, Poses, encoder_frames
from odocan.host.judge.silentboot import primed_in_silence
from odocan.host.judge.stream_refusal import NotStreamable
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.sim.robot import RobotProfile

MAX_PREFIX_FRAMES = 1 << 19  # frames held at most: 2 default chunks (~12 MB), ~24 min of pmir
TOO_LONG = ("the firmware's first count page says it primed after the log's first encoder "
            "frame, and its first pose or count page came after the first {frames} frames the "
            "stream holds (judged whole: powerup.primed_after)")
Accepted = npt.NDArray[np.bool_]


class PowerUpPrefix:
    """A life's first frames and their E2E verdicts, up to the chunk that holds its first
    accepted count page and ODOM_POSE_X (module docstring); dropped past the bound."""

    def __init__(self, decoder: BulkDecoder) -> None:
        self.decoder = decoder
        self.chunks: list[tuple[FrameArrays, Accepted]] = []
        self.held = 0
        self.page = self.pose = self.over = False

    @property
    def complete(self) -> bool:
        return self.page and self.pose

    def feed(self, chunk: FrameArrays, accepted: Accepted) -> None:
        if self.complete or self.over:
            return
        if self.held + len(chunk) > MAX_PREFIX_FRAMES:
            self.over, self.chunks = True, []
            return
        self.chunks.append((chunk, accepted.copy()))
        self.held += len(chunk)
        poses = self.decoder.select(chunk, "ODOM_POSE_X")
        self.pose = self.pose or bool(accepted[poses].any())
        try:
            page = self.decoder.decode_page(chunk, "ODOM_STATUS", ENC_E2E_PAGE)
        except DecodeError:
            return
        self.page = self.page or ("ENC_E2E_OK" in page and bool(accepted[page["index"]].any()))

    def event(self, t_s: float, judged: tuple[RobotProfile, str]) -> list[dict[str, Any]]:
        """``primedrange.primed_range_event`` of the life (``t_s``: its first sample's bus
        time, over the whole life); ``NotStreamable`` when the prefix was dropped."""
        if not self.complete:
            raise NotStreamable(TOO_LONG.format(frames=MAX_PREFIX_FRAMES))
        frames = concat_frames([c for c, _ in self.chunks])
        accepted = np.concatenate([a for _, a in self.chunks])
        enc = encoder_frames(frames, accepted, self.decoder)
        return primed_range_event(frames, accepted, self.decoder, enc, t_s, judged)

    def silent_event(self, t_s: float, head: Poses,
                     judged: tuple[RobotProfile, str]) -> list[dict[str, Any]]:
        """``silentboot.primed_in_silence`` of a life that rebooted unheard (``head``: its
        first sample); ``NotStreamable`` when the prefix was dropped before its first pose."""
        if self.over or not self.pose:
            raise NotStreamable(TOO_LONG.format(frames=MAX_PREFIX_FRAMES))
        frames = concat_frames([c for c, _ in self.chunks])
        accepted = np.concatenate([a for _, a in self.chunks])
        enc = encoder_frames(frames, accepted, self.decoder)
        return primed_in_silence(frames, self.decoder, enc, head, t_s, judged)


Pose = tuple[float, float, float]
Frames = Callable[[], Iterable[FrameArrays]]  # ``stream_first.Frames`` (it imports this one)


def cut_frames(frames: Frames, skip: int) -> Frames:
    """A life's frames (``stream_first.Frames``) from position ``skip`` on."""
    def chunks() -> Iterator[FrameArrays]:
        left = skip
        for chunk in frames():
            if left >= len(chunk):
                left -= len(chunk)
                continue
            yield chunk.select(slice(left, None)) if left else chunk
            left = 0
    return chunks


def judged_from_candidates(event: list[dict[str, Any]],
                           rerun: Callable[[Pose, int | None], tuple[dict[str, Any], float]],
                           whole: tuple[dict[str, Any], float] | None = None
                           ) -> tuple[dict[str, Any], float]:
    """The life judged from each candidate of ``event`` (``rerun``: the streamed life's report
    and first frame's time from that exact start, from the candidate's position on when it has
    one), as ``primedon.judged_from_each`` judges the whole log's (``whole``: the whole
    life's frame and E2E counts, ``primedon.COUNTED``, and first frame's time, for a cut)."""
    t_first: list[float] = []

    def analysis(pose: Pose, cut: int | None) -> Analysis:
        report, t_first_s = rerun(pose, cut)
        t_first[:] = [t_first_s if cut is None or whole is None else whole[1]]
        return Analysis(report=report, passed=bool(report["passed"]))

    counted = {} if whole is None else whole[0]
    best = judged_from_each(Analysis(report={"events": event, **counted}), analysis)
    return best.report, t_first[0]
