"""The replay engine: re-run a recorded drive against the current firmware build.

**Lockstep** (the default). The log's WHEEL_ENCODERS frames that pass the host's E2E check
(``host.e2e.check_frames``) are fed, byte for byte, to a ``sim.board.FirmwareBoard`` on python-can
``virtual`` buses, one firmware tick per 10 ms encoder period (after a reboot, the frames a
receiver fresh there takes: ``replay_boots``): each frame at the tick its bus time reached the
firmware, on the on-time frames' grid numbered by the sender's periods (``replay_arrival``: a
delayed frame is taken late), so a gap in the log is a run of ticks without a frame, exactly as
the firmware lived it (its E2E window widens, its watchdog may fire); a bus-off's ticks run
hearing nothing (``replay_sent.bus_off_silences``). Gaps longer than ``MAX_GAP_TICKS`` are
shortened to it. The firmware's clock is that grid's, 10 ms per tick; the log's own SIM_TRUTH
frames are put back on the bus where the log had them. Everything on the replayed bus is
analysed as ``odocan run`` does
(``host.analysis.analyze``, ``host.summary.finish``: same report keys, ``--report``, ``--plot``,
``--tolerance``, summary, exit 0/1/2), plus a ``replay`` section comparing the replayed on-board
poses with the ones in the log at the same encoder frames (identical for the same firmware).
``--log OUT`` writes the replayed bus. The integrator defaults to the one the log's ODOM_STATUS
reports (else exact); Ctrl-C stops early and checks what ran.

**Verdict.** PASS needs both: the replayed firmware within ``--tolerance`` of its float64
reference (as ``odocan run``), and within ``--tolerance`` of the firmware that recorded the log
(the logged on-board poses at the same encoder frames; positions up to the log's first gap of the
encoder sequence, since across a gap the recording firmware may have had frames the log lacks,
after it their offset between two gaps, which one firmware keeps (``drift_between_gaps_m``;
checked when the log says its firmware took its frames on time, ``replayable``),
headings everywhere, since they are exact across gaps; every pose the log sent for a frame, a
resend too, and the log's resent positions against its first at the same frame everywhere:
one firmware's poses at one frame agree; a log cut mid-drive, and after each hole of the log,
compared from their first common frame: ``replay_compare``). The firmware runs as many ticks
without a frame before the log's first as put its poses in the log's phase
(``replay_compare.pose_phase_ticks``). When the replay departs, the cause is
looked for by name (``diagnose``): the integrator the log's ODOM_STATUS reports against the one
replayed, and which robot profile (the one given and every shipped one) the logged poses fit
(``analyze`` of the log itself, no replay: the profile whose float64 odometry of the logged
counts the logged poses follow within tolerance).
"""

from __future__ import annotations

import itertools
import sys
import time
from contextlib import nullcontext
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import can
import numpy as np
import numpy.typing as npt
from can.interfaces.virtual import VirtualBus

from odocan.firmware.config import RobotParams
from odocan.host.io.logs import (
    FrameArrays,
    FrameCollector,
    to_message,
)
from odocan.host.io.recording import Recording
from odocan.host.judge.analysis import Analysis, Tolerance, analyze
from odocan.host.judge.diagnosis import fitting_profiles
from odocan.host.judge.replay_arrival import FedTicks, fed_plan, fed_ticks
from odocan.host.judge.replay_boots import boot_starts, fresh_accepted, fresh_ticks
from odocan.host.judge.replay_compare import (
    onboard_by_tick,
    pose_phase_ticks,
    starts_mid_drive,
    versus_log,
)
from odocan.host.judge.replay_deaf import DeafBus
from odocan.host.judge.replay_events import (
    clock_steps_s,
    fed_events,
    late_ticks,
    unfed_truth,
)
from odocan.host.judge.replay_halts import fit_halts
from odocan.host.judge.replay_jumps import JumpModel
from odocan.host.judge.replay_lives import LifePlan, fit_first_prime, judge_lives, plan_lives
from odocan.host.judge.replay_track import EncoderTrack, late_frames
from odocan.host.outputs import OutputError
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e import check_frames
from odocan.host.stopped import Stopped, interruption, signum_of
from odocan.sim import contract
from odocan.sim.board import TICK_S, FirmwareBoard
from odocan.sim.clock import LockstepClock
from odocan.sim.closing import release_all
from odocan.sim.exceptions import OdocanError
from odocan.sim.realtime import StopRequest, stop_on_signals
from odocan.sim.rig import INTEGRATORS, firmware_params
from odocan.sim.robot import RobotProfile, list_profiles
from odocan.sim.tickloop import TickLoop, deliver

IntArray = npt.NDArray[np.int64]
# One fresh in-process channel per replay, numbered (not id()-named) so two runs of the same
# command write the same bytes to --log.
_REPLAY_CHANNELS = itertools.count(1)


class ReplayError(OdocanError):
    """A log that cannot be replayed (no encoder frame, ...)."""


# --- what is fed -------------------------------------------------------------------------------


@dataclass(frozen=True)
class ReplayInput:
    """What a log gives the replay: the encoder frames to feed, and the SIM_TRUTH frames."""

    accepted: npt.NDArray[np.bool_]  # E2E verdict of every frame of the log
    encoders: EncoderTrack
    truth: IntArray  # positions of the SIM_TRUTH frames (all of them, as logged)
    rejected_encoders: int  # WHEEL_ENCODERS frames the E2E check dropped
    late: IntArray = field(default_factory=lambda: np.zeros(0, np.int64))  # fed anyway,
    late_tick: IntArray = field(default_factory=lambda: np.zeros(0, np.int64))  # ``late_frames``
    fed: FedTicks | None = None  # the tick each reached the firmware (``replay_arrival``)

    @classmethod
    def from_log(cls, frames: FrameArrays) -> ReplayInput:
        """Check the log's frames; ``ReplayError`` without an encoder frame to feed."""
        decoder = BulkDecoder(contract.database())
        _, accepted = check_frames(frames)  # a rebooted firmware's receiver fresh: replay_boots
        starts = [start for start, _ in boot_starts(frames, decoder)]
        accepted = fresh_accepted(frames, accepted, starts, decoder)
        encoders = fresh_ticks(EncoderTrack.of(frames, accepted, decoder), starts)
        total = len(decoder.select(frames, "WHEEL_ENCODERS"))
        if total == 0:
            raise ReplayError("no WHEEL_ENCODERS frame (ID 0x100, 8 bytes) in the log: "
                              "nothing to feed the firmware")
        if len(encoders.index) == 0:
            raise ReplayError(f"none of the {total} WHEEL_ENCODERS frames passes its E2E check")
        truth = decoder.select(frames, "SIM_TRUTH").astype(np.int64)
        late, _ = late_frames(frames, accepted, encoders)
        fed = fed_ticks(frames, encoders, late)
        return cls(accepted, encoders, truth, total - len(encoders.index), late, fed.late, fed)

    @property
    def arrival(self) -> FedTicks:
        """``fed``, or the sender's periods as they are (a feed built by hand)."""
        return self.fed or FedTicks(self.encoders, self.encoders.tick, self.late_tick,
                                    float(self.encoders.timestamp_s[0]))


def logged_integrator(frames: FrameArrays, accepted: npt.NDArray[np.bool_]) -> str | None:
    """The integrator the log's last accepted ODOM_STATUS summary reports (None: none)."""
    decoder = BulkDecoder(contract.database())
    try:
        page = decoder.decode_page(frames, "ODOM_STATUS", 0)
    except DecodeError:
        return None
    values = page["INTEGRATOR"][accepted[page["index"]]]
    if len(values) == 0:
        return None
    signal = decoder.message("ODOM_STATUS").get_signal_by_name("INTEGRATOR")
    choices: dict[Any, Any] = dict(signal.choices or {})
    name = str(choices.get(int(values[-1]), "")).lower()
    return name if name in INTEGRATORS else None


# --- the lockstep replay -------------------------------------------------------------------


class LockstepReplay:
    """The firmware on python-can ``virtual`` buses, fed a log's frames one tick at a time.

    Three handles on one channel, as in ``sim.rig``: the log's side (sends the encoder and truth
    frames), the firmware's board, and the host's observer (drained into ``listeners``).
    """

    def __init__(
        self, params: RobotParams, listeners: list[can.Listener], channel: str
    ) -> None:
        self.clock = LockstepClock()
        self._buses = [VirtualBus(channel=channel, preserve_timestamps=True,
                                  receive_own_messages=False) for _ in range(3)]
        self._log_bus, fw_bus, host_bus = self._buses
        self._controller = DeafBus(fw_bus)  # bus-off on the plan's ``deaf`` ticks
        self.board = FirmwareBoard(self._controller, params, self.clock)
        self.listeners = listeners
        self.loop = TickLoop(self._work, host_bus, listeners, self.clock)
        self.stopped: Stopped | None = None  # by a signal, before the log's end
        self.fed = 0  # encoder frames fed to the firmware (the host's E2E check refused
        self.late_fed = 0  # ``late_fed`` of them: ``replay_track.late_frames``)
        self.halted: set[int] = set()  # ticks the board runs none (``replay_lives``)
        self.deaf: set[int] = set()  # ticks its controller is bus-off: it hears nothing
        self.resets: dict[int, bool] = {}  # encoder frame number -> reset after it is sent
        self.held: dict[int, int] = {}  # log position -> tick: fed once the ticks before ran

    @property
    def ticks(self) -> int:
        """Firmware ticks run so far."""
        return self.loop.ticks

    def _work(self, k: int) -> None:
        """The nodes' work in a tick: the firmware's board alone (the log is the rest), none
        while the log shows its firmware halted or not yet powered up (``replay_lives``)."""
        self._controller.deaf = k in self.deaf  # bus-off: it neither hears nor sends
        if k not in self.halted:
            self.board.run_tick()

    def deaf_s(self) -> tuple[tuple[float, float], ...]:
        """The bus-off ticks as bus times [first tick's start, the first heard tick's start]."""
        ticks = sorted(self.deaf)
        runs = [k for i, k in enumerate(ticks) if i == 0 or ticks[i - 1] != k - 1]
        ends = [k + 1 for i, k in enumerate(ticks) if i + 1 == len(ticks) or ticks[i + 1] != k + 1]
        return tuple((self.loop.start_s + a * TICK_S, self.loop.start_s + b * TICK_S)
                     for a, b in zip(runs, ends, strict=True))

    def _reset(self, which: int, after: bool) -> None:
        """A fresh firmware where the log's powered up (``replay_lives.LifePlan.resets``): the
        board reset and its receive FIFO cleared with it."""
        if self.resets.get(which) is after:
            self.board.reboot()
            while self.board.bus.recv(0) is not None:
                pass

    def run(self, frames: FrameArrays, feed: ReplayInput, phase_ticks: int = 0,
            stop: StopRequest | None = None) -> None:
        """Feed every encoder frame at its tick (the log's truth frames where they were), after
        ``phase_ticks`` ticks without a frame (``replay_compare.pose_phase_ticks``); Ctrl-C or
        SIGTERM stops it between two encoder frames, a second one at once (``stopped``: how
        far it got; ``fed``: the encoder frames fed). ``stop``: the request the caller's
        ``stop_on_signals`` already sets (else the run installs its own)."""
        enc, arrival = feed.encoders, feed.arrival
        self.loop.start_s = arrival.start_s - phase_ticks * TICK_S
        self.loop.run_to(phase_ticks)
        held = self._held_fed(frames, feed, phase_ticks)
        hidden = unfed_truth(frames, feed.truth, held)
        late = late_ticks(feed.late, feed.late_tick, phase_ticks, len(frames.can_id), held)
        events = fed_events(enc.index, feed.truth, held, late)
        shift_s = clock_steps_s(frames.timestamp_s)
        due: int | None = None  # the tick whose encoder frame is on the bus, not yet run
        own = stop is None
        stop = StopRequest() if stop is None else stop
        interrupt: KeyboardInterrupt | None = None
        try:
            with stop_on_signals(stop) if own else nullcontext():
                for position, which in events:
                    # held by a halted board's FIFO: fed after the tick before the halt ran
                    self.loop.run_to(held.get(position, 0))
                    if which == -3 and not self._late(late[position], due):
                        continue  # before the first frame, or a halted board's: lost
                    if which >= 0:  # an encoder frame: first run the ticks before its own
                        if stop.stop_requested:
                            break
                        due = self._to_tick(int(arrival.tick[which]) + phase_ticks, due)
                        self._reset(which, False)
                    message = to_message(frames, position)
                    message.timestamp += float(shift_s[position])
                    self._send(message, position in hidden)
                    if which >= 0:
                        self._reset(which, True)
                else:
                    if due is not None:
                        self.loop.run_to(due + 1)
        except KeyboardInterrupt as exc:
            interrupt = exc
        if stop.stop_requested or interrupt is not None:
            asked_s = (int(arrival.tick[-1]) + 1 + phase_ticks) * TICK_S
            self.stopped = Stopped(stop.signum or signum_of(interrupt),
                                   round(self.ticks * TICK_S, 6), round(asked_s, 6))
            if self.fed:  # none: the caller's one line says so
                print(f"interrupted after {self.ticks * TICK_S:g} s of the log", file=sys.stderr)

    def _late(self, tick: int, due: int | None) -> bool:
        """Run the ticks before ``tick``, where a frame the host refused reached the firmware
        (``replay_track.late_frames``), to feed it: False when it is lost (before the first fed
        frame, or in a halted board's tick)."""
        if due is None or tick in self.halted:
            return False
        self._to_tick(tick, due)
        self.late_fed += 1
        return True

    def _to_tick(self, tick: int, due: int | None) -> int:
        """Run the ticks before ``tick`` (none before the first frame fed: ``due`` None), set
        the clock to its start, count the frame fed at it."""
        if due is not None:
            self.loop.run_to(tick)
        self.clock.advance_to(self.loop.start_s + tick * TICK_S)
        self.fed += 1
        return tick

    def _send(self, message: can.Message, firmware_only: bool) -> None:
        """Put a log's frame on the bus, or (``_unfed_truth``) into the firmware's handle's
        receive queue alone, as python-can's virtual bus does for each handle but the sender."""
        if firmware_only:
            self._buses[1].queue.put(message)
        else:
            self._log_bus.send(message)

    def _held_fed(self, frames: FrameArrays, feed: ReplayInput,
                  phase_ticks: int) -> dict[int, int]:
        """``held``, its ticks ``phase_ticks`` later, less those past the end of ``frames`` (a
        prefix of the log, tried). A truth frame not fed (a log cut mid-drive) is kept: it took
        a slot of the recording board's FIFO (``_unfed_truth``)."""
        return {p: t + phase_ticks for p, t in self.held.items() if p < len(frames.can_id)}

    def _drain(self) -> None:
        deliver(self.loop.host_bus, self.listeners)

    def close(self) -> None:
        """Deliver what is left, stop the listeners, release the buses: every one, even when
        a listener's ``stop()`` fails (the first error is raised once all are released)."""
        release_all([self._drain, *(li.stop for li in self.listeners),
                     self._controller.shutdown, *(bus.shutdown for bus in self._buses)])


def _unanalysed(signum: int | None, replay: LockstepReplay, log_out: Path | None,
                opened: bool) -> KeyboardInterrupt:
    """What a signal that leaves nothing to analyse raises once the replay is closed: one
    before the first encoder frame was fed (``--log OUT`` finished with no frame, or, heard
    before it was opened, not written), or one heard as the last frame ran or the log was
    finished (as it would be in the analysis)."""
    if replay.stopped is None and replay.fed:
        return interruption(signum, "after its last tick, before the analysis")
    where = "before its first tick"
    if log_out is not None:
        where += f"; --log {log_out}: " + ("finished, no frame" if opened else "not written")
    return interruption(signum, where)


def diagnose(
    log: FrameArrays, accepted: npt.NDArray[np.bool_], profile: RobotProfile, integrator: str,
    tolerance: Tolerance, *, source: str = "LOG", robot_arg: str | None = None,
    given_as: str = "--robot",
) -> list[str]:
    """The likely cause of a departure, by name: an integrator other than the log's, a robot
    profile other than the one the logged poses fit (module docstring, "Verdict"); when none
    fits, either the profile or the recording firmware (``source``: the log's name, and
    ``robot_arg``: the --robot given, for the command that says which poses are off;
    ``given_as``: how a robot mismatch names ``profile``, "the default robot" without one)."""
    reasons = []
    logged = logged_integrator(log, accepted)
    if logged is not None and logged != integrator:
        reasons.append(f"integrator mismatch: the log's ODOM_STATUS reports {logged}, the replay "
                       f"ran {integrator}")
    made: dict[str, Analysis] = {}  # the fit's analyses, each made once
    fits = fitting_profiles(log, profile, logged or integrator, tolerance, analyses=made)
    if profile.name in fits:
        if logged is None or logged == integrator:  # the fit's own call: its analysis
            lived = unreplayable(made[profile.name].report)
            reasons.append(f"the log fits robot {profile.name!r} with the {integrator} "
                           + ("integrator, but its firmware lived what a lockstep replay does "
                              f"not reproduce: {'; '.join(lived)}" if lived else
                              "integrator: the firmware build differs from the one that "
                              "recorded it"))
    elif fits:
        reasons.append(f"robot mismatch: the log's poses fit robot {', '.join(map(repr, fits))}, "
                       f"not {profile.name!r} ({given_as})")
    else:
        robot = robot_arg or profile.name
        reasons.append(f"the log's poses fit no known robot profile ({profile.name!r} given, "
                       f"{', '.join(list_profiles())} shipped): either its robot is another "
                       "(give its profile with --robot) or the firmware that recorded it was "
                       f"off the float64 reference (odocan analyze {source} --robot {robot} "
                       "says which poses)")
    return reasons


# ERROR_MASK bits that say the recording firmware's timing was not one frame per tick
_TIMING_BITS = ("TIME_LOST", "MAILBOX_OVERFLOW")


def unreplayable(report: dict[str, Any]) -> list[str]:
    """What the firmware that recorded a log lived and a lockstep replay does not reproduce,
    from ``analyze``'s report of the log: reboots (the replay runs one life), lost time or
    dropped frames (the replay feeds every frame on its tick), encoder frames out of sequence
    (late or repeated: the replay feeds only those the host's E2E check accepts, in order, and
    the recording firmware may have taken a late one). Empty: nothing of the kind, so a
    departure points at the build."""
    causes = []
    reboots = report.get("reboots") or []
    if reboots:
        causes.append(f"{len(reboots)} firmware reboot{'s' if len(reboots) > 1 else ''} (first "
                      f"at {float(reboots[0]['t_s']):.2f} s; a replay runs one firmware life)")
    bits = sorted({str(e.get("bit")) for e in report.get("firmware_events", [])
                   if e.get("kind") == "error_bit" and e.get("bit") in _TIMING_BITS})
    if bits:
        causes.append(f"its ERROR_MASK reports {', '.join(bits)} (a replay runs every tick on "
                      "time)")
    e2e = (report.get("e2e") or {}).get("WHEEL_ENCODERS") or {}
    out_of_sequence = int(e2e.get("wrong_sequence", 0)) + int(e2e.get("repeated", 0))
    if out_of_sequence:
        causes.append(f"{out_of_sequence} WHEEL_ENCODERS frames out of sequence (late or "
                      "repeated: the replay feeds the accepted ones in order, the recording "
                      "firmware may have taken a late one)")
    return causes


def _replayed_head(frames: FrameArrays, profile: RobotProfile, integrator: str,
                   plan: LifePlan, phase: int = 0, truth: bool = False) -> FrameArrays:
    """The replayed bus of ``frames``, a prefix of a log, under ``plan`` (unrecorded; its
    truth frames fed when ``truth``, ``phase`` ticks first): a candidate of
    ``replay_lives.fit_first_prime`` or ``replay_halts.fit_halts``."""
    collector = FrameCollector()
    feed = ReplayInput.from_log(frames)
    replay = LockstepReplay(firmware_params(profile, integrator), [collector],
                            f"odocan-replay-{next(_REPLAY_CHANNELS)}")
    try:
        _apply(replay, plan, feed.arrival, phase)
        replay.run(frames, feed if truth else replace(feed, truth=feed.truth[:0]), phase)
    finally:
        replay.close()
    return collector.arrays()


def _first_change(plan: LifePlan, encoders: EncoderTrack) -> int | None:
    """The tick of the log's second firmware life or first stall, whichever comes first (None:
    neither): the replay's pose phase is the first life's before it (a stall of an odd number
    of ticks shifts the firmware's own pose phase; a longer part after it outvoted the part
    before, whose poses the replay then paired none of)."""
    ticks = [int(encoders.tick[s]) for s in plan.starts[1:2]] + [h[0] for h in plan.halts[:1]]
    return min(ticks, default=None)


def _apply(replay: LockstepReplay, plan: LifePlan, arrival: FedTicks, phase: int) -> None:
    """Set ``replay`` to live ``plan`` (its ticks ``phase`` later): halts, resets, held frames."""
    halted, replay.held, deaf = fed_plan(plan, arrival)
    replay.halted = {t + phase for t in halted}
    replay.deaf = {t + phase for t in deaf}
    replay.resets = plan.resets


def replay_and_analyze(
    frames: FrameArrays, feed: ReplayInput, profile: RobotProfile, integrator: str, *,
    tolerance: Tolerance, log: Path, log_out: Path | None = None,
) -> Analysis:
    """Run the replay (every frame it puts on its bus written to ``log_out`` when given),
    analyse the replayed bus, add the ``replay`` section. A log that starts mid-drive has its
    SIM_TRUTH frames left off the replayed bus (``truth_compared`` False): the replayed firmware
    starts from (0, 0, 0) on the log's first encoder frame, the truth from where the drive was,
    so their difference is the cut's pose, no error of the firmware (the trial: 1563 mm)."""
    collector = FrameCollector()
    listeners: list[can.Listener] = [collector]
    stop = StopRequest()
    with stop_on_signals(stop):  # from the log's opening to its end: a signal only asks
        channel = f"odocan-replay-{next(_REPLAY_CHANNELS)}"
        recording = None if log_out is None or stop.stop_requested else \
            Recording(can.Logger(log_out), channel)  # a full disk stops it, not the replay
        listeners += [] if recording is None else [recording]
        try:
            replay = LockstepReplay(firmware_params(profile, integrator), listeners, channel)
        except BaseException:
            release_all([li.stop for li in listeners])  # the log opened is finished
            raise
        start = time.perf_counter()
        try:  # mid-drive the replay starts from (0, 0, 0), the log's truth elsewhere: left out
            truth_compared = not starts_mid_drive(
                frames, feed.accepted, onboard_by_tick(frames, feed.accepted), feed.encoders)
            plan = fit_first_prime(
                frames, feed.accepted, feed.encoders, plan_lives(frames, feed.accepted,
                                                                 feed.encoders), tolerance,
                lambda head, tried: _replayed_head(head, profile, integrator, tried))
            phase = 0 if plan.powered else pose_phase_ticks(frames, feed.accepted,
                                                            _first_change(plan, feed.encoders))
            plan = fit_halts(frames, feed.accepted, feed.encoders, plan, tolerance,
                             lambda head, tried: _replayed_head(
                                 head, profile, integrator, tried, phase, truth_compared))
            _apply(replay, plan, feed.arrival, phase)
            if not stop.stop_requested:
                replay.run(frames, feed if truth_compared else replace(feed, truth=feed.truth[:0]),
                           phase, stop)
        finally:
            try:
                replay.close()
            except OSError as exc:
                raise OutputError(f"--log {log_out}: {exc.strerror or exc}") from None
    if stop.stop_requested and (replay.stopped is None or replay.fed == 0):
        raise _unanalysed(stop.signum, replay, log_out, recording is not None)
    wall_s = time.perf_counter() - start
    replayed = collector.arrays()
    jumps = replace(JumpModel.of(profile, integrator), deaf_s=replay.deaf_s())
    analysis = analyze(replayed, profile, integrator, tolerance=tolerance,
                       wall_seconds=wall_s)
    analysis.report["replay"] = {
        "log": str(log),
        "encoder_frames_fed": replay.fed, "encoder_frames_fed_late": replay.late_fed,
        "encoder_frames_rejected": feed.rejected_encoders,
        "truth_frames": len(feed.truth),
        "truth_compared": truth_compared,
        "ticks": replay.ticks,
        "ticks_without_frame": replay.ticks - min(replay.ticks, len(feed.encoders.index)),
        "interrupted": replay.stopped is not None,
        "onboard_vs_log": versus_log(frames, feed.accepted, replayed,
                                     jumps=jumps),
    }
    if not plan.trivial:
        _, replayed_accepted = check_frames(replayed)
        analysis.report["replay"]["lives"] = judge_lives(
            frames, feed.accepted, replayed, replayed_accepted, feed.encoders, plan, tolerance,
            jumps)
    if replay.stopped is not None:
        analysis.report["stopped"] = replay.stopped.as_dict()
    return analysis


