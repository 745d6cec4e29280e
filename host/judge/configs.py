"""ODOM_CONFIG applied inside a log (issue #11 point 6): ``analyze`` cuts the log there and judges
the part after it as a new life with the firmware's new robot, as the live judge does
(``host.judge.liveconfig``: its ``ConfigFollower``, run here over the log's accepted ODOM_CONFIG,
ODOM_AUTH, ODOM_ACK and WHEEL_ENCODERS frames in bus order).

A parameter is staged when its ACK is heard; the APPLY's ACK makes the staged set (the others
kept) the robot from then on: geometry, counter width, integrator, speed bound. The firmware acts
on the APPLY when it drains it (with SecOC, when its ODOM_AUTH arrives), after the encoder
frames before it: the latest of them was its last step with the old robot, so the new life
starts there (its reference steps from it with the new robot, its start fitted to the samples,
as a log that starts mid-drive: the firmware keeps its pose). A new counter width re-primes the
firmware (``Odometry.unprime``): the life then starts at the first encoder frame after the APPLY.
A NACKed APPLY changes nothing. A reboot brings the firmware up with its build's robot again: the
lives after it are judged with the log's robot until the next config; the parameters staged
before it are lost with the firmware's RAM (``ConfigFollower.forget`` at each firmware life's
start, ``setposes.reboot_positions``): a bare APPLY after a reboot applies nothing of them
(the ODOM_ACKs E2E-checked afresh in each life, ``stagedacks``).

The PROFILE page is judged against the parameters in force: the pages before the first APPLY
against ``--robot`` (``running_before_configs``), those after each APPLY against the robot it
applied (``later_mismatches``). The streamed analysis cuts at the same
configs (``stream_cuts``: ``cuts_of`` of the rows it gathers chunk by chunk).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.liveconfig import INTEGRATORS, PARAMS, ConfigFollower
from odocan.host.judge.profilepage import (
    RunningProfile,
    profile_mismatch,
    running_profile,
    running_profile_of,
    with_bus_speed,
)
from odocan.host.judge.reboots import Life
from odocan.host.judge.reference import PROFILE_SPEED, SpeedBound
from odocan.host.judge.samples import AnalysisError, pick_integrator
from odocan.host.judge.setposes import followed_rows
from odocan.host.protocol import busfacts
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e import check_frames
from odocan.sim.robot import MM_PER_M, RobotProfile

APPLY_PARAM = busfacts.APPLY_PARAM  # ODOM_CONFIG PARAM / ODOM_ACK REQUEST_FIELD of APPLY
CONFIG_REQUEST = 2  # ODOM_AUTH REQUEST naming ODOM_CONFIG (the DBC's VAL_)
NM_PER_M = 1_000_000_000
_UNITS = {"WHEEL_RADIUS_LEFT": NM_PER_M, "WHEEL_RADIUS_RIGHT": NM_PER_M, "WHEELBASE": NM_PER_M,
          "MAX_WHEEL_SPEED": MM_PER_M}  # raw LSBs per DBC unit (nm, mm/s); the others: 1


@dataclass(frozen=True)
class ConfigCut:
    """An applied config: ``position``, the log position where its life starts (module
    docstring); ``apply_position``, the APPLY's (or its ODOM_AUTH's): the firmware runs with
    the new robot from there; ``t_s``, the bus time of its ACK; ``staged``, the parameters it
    applied (PARAM: m, m/s, counts, bits, raw INTEGRATOR)."""

    position: int
    apply_position: int
    t_s: float
    staged: dict[str, float]

    def robot(self, before: RobotProfile) -> RobotProfile:
        """``before`` with the applied parameters (on the nm and mm/s grids, as the wire)."""
        s = self.staged
        return dataclasses.replace(
            before, counts_per_rev=int(s.get("COUNTS_PER_REV", before.counts_per_rev)),
            wheel_radius_left_m=s.get("WHEEL_RADIUS_LEFT", before.wheel_radius_left_m),
            wheel_radius_right_m=s.get("WHEEL_RADIUS_RIGHT", before.wheel_radius_right_m),
            wheelbase_m=s.get("WHEELBASE", before.wheelbase_m),
            counter_bits=int(s.get("COUNTER_BITS", before.counter_bits)),
            max_wheel_speed_m_s=s.get("MAX_WHEEL_SPEED", before.max_wheel_speed_m_s))

    def integrator(self, before: str) -> str:
        """The integrator applied (``before`` when INTEGRATOR was not staged)."""
        raw = int(self.staged.get("INTEGRATOR", -1))
        return INTEGRATORS[raw] if 0 <= raw < len(INTEGRATORS) else before


def config_cuts(frames: FrameArrays, decoder: BulkDecoder, counter_bits: int) -> list[ConfigCut]:
    """The applied configs of the log, in bus order (module docstring; ``counter_bits``: the
    log's robot's, to tell a new width). The E2E check runs only when an ODOM_ACK of an
    ODOM_CONFIG APPLY is in the log at all."""
    try:
        raw = decoder.decode(frames, "ODOM_ACK")
        config_id = decoder.message("ODOM_CONFIG").frame_id
    except (DecodeError, KeyError):
        return []
    if not ((raw["REQUEST_ID"] == config_id) & (raw["REQUEST_FIELD"] == APPLY_PARAM)).any():
        return []
    rows, encoders, reboots = followed_rows(frames, decoder, COMMANDS)
    return cuts_of(rows, encoders, decoder, counter_bits, reboots)


COMMANDS = ("ODOM_CONFIG", "ODOM_AUTH", "ODOM_ACK")  # the accepted rows ``cuts_of`` follows


def cuts_of(rows: dict[str, dict[str, np.ndarray]], encoders: npt.NDArray[np.intp],
            decoder: BulkDecoder, counter_bits: int, reboots: Sequence[int] = ()
            ) -> list[ConfigCut]:
    """``config_cuts`` from the log's accepted rows of ``COMMANDS`` (``optional_rows``, their
    index the log position) and the log positions of its accepted encoder frames (``encoders``:
    at least the latest before and the first after each of those rows); ``reboots``: where
    the firmware lives after the first start (``setposes.reboot_positions``)."""
    commands, auths, acks = (rows[name] for name in COMMANDS)
    config_id = decoder.message("ODOM_CONFIG").frame_id
    steps = sorted(
        [(int(i), "boot", -1) for i in reboots]
        + [(int(i), "cmd", k) for k, i in enumerate(commands["index"].tolist())]
        + [(int(i), "auth", k) for k, i in enumerate(auths["index"].tolist())
           if int(auths["REQUEST"][k]) == CONFIG_REQUEST]
        + [(int(i), "ack", k) for k, i in enumerate(acks["index"].tolist())
           if int(acks["REQUEST_ID"][k]) == config_id])
    return _follow(steps, commands, acks, encoders, counter_bits)


def _follow(steps: list[tuple[int, str, int]], commands: dict[str, np.ndarray],
            acks: dict[str, np.ndarray], encoders: npt.NDArray[np.intp],
            counter_bits: int) -> list[ConfigCut]:
    """``ConfigFollower`` over the frames in bus order; the APPLY's (or its ODOM_AUTH's) log
    position is noted for its cut."""
    follower, cuts, apply_at = ConfigFollower(), [], -1
    for position, kind, k in steps:
        if kind == "cmd":
            param_raw = int(commands["PARAM"][k])
            param = "APPLY" if param_raw == APPLY_PARAM else PARAMS[param_raw] \
                if param_raw < len(PARAMS) else str(param_raw)
            value = None
            if param in PARAMS and param in commands:  # raw: in the wire's LSBs
                value = int(commands[param][k]) / _UNITS.get(param, 1)
            follower.on_frame(int(commands["COUNTER"][k]), param, value)
            apply_at = position if param == "APPLY" else apply_at
        elif kind == "auth":
            apply_at = position if apply_at >= 0 else apply_at
        elif kind == "boot":  # the firmware's staging was in its RAM
            follower.forget()
            apply_at = -1
        else:
            staged = follower.on_ack(int(acks["REQUEST_COUNTER"][k]), int(acks["RESULT"][k]) == 0,
                                     request_field=_field(acks, k))
            if staged is not None and apply_at >= 0:
                bits = int(staged.get("COUNTER_BITS", counter_bits))
                cuts.append(ConfigCut(_life_start(encoders, apply_at, bits != counter_bits),
                                      apply_at, float(acks["timestamp_s"][k]), staged))
                counter_bits = bits
    return cuts


def _field(acks: dict[str, np.ndarray], k: int) -> int | None:
    """The REQUEST_FIELD of ODOM_ACK row ``k`` (None: a DBC without it)."""
    return int(acks["REQUEST_FIELD"][k]) if "REQUEST_FIELD" in acks else None


def _life_start(encoders: npt.NDArray[np.intp], apply_at: int, reprimes: bool) -> int:
    """The latest accepted encoder frame before the APPLY; the first after it when the firmware
    re-primes (a new counter width); the APPLY itself when there is none."""
    at = int(np.searchsorted(encoders, apply_at))
    if reprimes:
        return int(encoders[at]) if at < len(encoders) else apply_at
    return int(encoders[at - 1]) if at > 0 else apply_at


def cut_configs(lives: list[Life], cuts: list[ConfigCut]) -> list[Life]:
    """``lives`` cut again at each applied config: the part from the cut's position on is a new
    life (``Life.config``), judged with the robot it applied."""
    for cut in cuts:
        for k, life in enumerate(lives):
            inside = life.index >= cut.position
            if 0 < int(np.count_nonzero(inside)) < len(life.index):
                head = dataclasses.replace(life, index=life.index[~inside])
                tail = Life(life.index[inside], boot=False, t_s=cut.t_s, config=cut)
                lives = [*lives[:k], head, tail, *lives[k + 1:]]
                break
    return lives


def in_force(lives: list[Life], robot: RobotProfile, integrator: str,
             bound: SpeedBound) -> list[tuple[RobotProfile, str, SpeedBound]]:
    """The robot, integrator and speed bound each life is judged with (module docstring): a
    config's speed bound is the one it applied (``bound`` None, no gate, stays None)."""
    now, judged = (robot, integrator, bound), []
    for life in lives:
        if life.config is not None:
            speed = PROFILE_SPEED if "MAX_WHEEL_SPEED" in life.config.staged else now[2]
            now = (life.config.robot(now[0]), life.config.integrator(now[1]),
                   None if bound is None else speed)
        elif life.boot or (life.t_s is not None and life.set_pose is None):  # a reboot
            now = (robot, integrator, bound)
        judged.append(now)
    return judged


def running_before_configs(frames: FrameArrays, counter_bits: int) -> RunningProfile | None:
    """``running_profile`` of the frames before the first applied config's APPLY (odocan's DBC;
    all of them when none): what the firmware ran with as ``--robot`` (``counter_bits``:
    its), its speed bound and its PROFILE_CRC."""
    decoder = BulkDecoder(default_plan())
    cuts = config_cuts(frames, decoder, counter_bits)
    head = frames if not cuts else frames.select(np.arange(cuts[0].apply_position))
    return running_profile(head, decoder)


def later_mismatches(frames: FrameArrays, robot: RobotProfile, integrator: str) -> list[str]:
    """The PROFILE pages after each applied config (odocan's DBC) judged against the robot it
    applied (the last page before the next config's APPLY): one line per config whose page
    differs."""
    decoder = BulkDecoder(default_plan())
    cuts = config_cuts(frames, decoder, robot.counter_bits)
    ends = [c.apply_position for c in cuts[1:]] + [len(frames)] * bool(cuts)
    return mismatch_lines([(cut, running_profile(frames.select(np.arange(
        cut.apply_position, end)), decoder)) for cut, end in zip(cuts, ends, strict=True)],
        robot, integrator)


def mismatch_lines(pages: list[tuple[ConfigCut, RunningProfile | None]], robot: RobotProfile,
                   integrator: str) -> list[str]:
    """``later_mismatches``' lines from each applied config's page (``running_profile`` of
    the frames from its APPLY to the next one's)."""
    said = []
    for cut, page in pages:
        robot, integrator = cut.robot(robot), cut.integrator(integrator)
        text = profile_mismatch(page, robot, integrator)
        if text is not None:
            said.append(f"after the config applied at {cut.t_s:.3f} s: {text}")
    return said


@dataclass
class ConfigPages:
    """The PROFILE pages around the applied configs of a streamed log (the CLI's checks of
    ``running_before_configs`` and ``later_mismatches``, which read the whole log): read from
    the streamed judge's spilled frames (``read``) once it found the configs. ``profile``: the
    robot as given, without the bus's speed bound."""

    profile: RobotProfile
    before: RunningProfile | None = None  # the page before the first APPLY
    after: list[tuple[ConfigCut, RunningProfile | None]] = dataclasses.field(
        default_factory=list)

    def read(self, cuts: list[ConfigCut],
             between: Callable[[int, int], Iterable[FrameArrays]], n_frames: int) -> RobotProfile:
        """The pages of the log's ``n_frames`` frames (``between``: the frames [lo, hi), chunk
        by chunk) around ``cuts``; the robot to judge with (``running_before_configs``')."""
        self.before = running_profile_of(between(0, cuts[0].apply_position))
        ends = [c.apply_position for c in cuts[1:]] + [n_frames]
        self.after = [(cut, running_profile_of(between(cut.apply_position, end)))
                      for cut, end in zip(cuts, ends, strict=True)]
        return with_bus_speed(self.profile, self.before)

    def running(self, head: RunningProfile | None) -> RunningProfile | None:
        """The page the firmware ran with as ``--robot``: before the first config when one
        was applied, else the log's head's (``head_profile``)."""
        return self.before if self.after else head

    def mismatches(self, integrator: str) -> list[str]:
        return mismatch_lines(self.after, self.profile, integrator)


def first_integrator(frames: FrameArrays, lives: list[Life], decoder: BulkDecoder,
                      integrator: str, source: str) -> str:
    """The integrator ODOM_STATUS reports before the first applied config (a config may
    change it: ``pick_integrator`` tells the last); ``integrator`` when given or no config."""
    cut = next((life.config for life in lives if life.config is not None), None)
    if cut is None or source != "ODOM_STATUS":
        return integrator
    head = frames.select(np.arange(cut.apply_position))
    try:
        return pick_integrator(head, check_frames(head, decoder.db)[1], decoder, None)[0]
    except AnalysisError:  # no summary before it: the last one reported
        return integrator
