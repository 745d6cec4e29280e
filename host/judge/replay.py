"""The replay engine: re-run a recorded drive against the current firmware build.

**Lockstep** (the default). The log's WHEEL_ENCODERS frames that pass the host's E2E check
(``host.e2e.check_frames``) are fed, byte for byte, to a ``sim.board.FirmwareBoard`` on python-can
``virtual`` buses, one firmware tick per 10 ms encoder period: the frames' ticks come from the
sender's sequence (the E2E COUNTER unwrapped, widened by 16 where the timestamps say so, as
``host.analysis`` does), so a gap in the log is a run of ticks without a frame, exactly as the
firmware would have lived it (its E2E window widens, its watchdog may fire). Gaps longer than
``MAX_GAP_TICKS`` are shortened to it. The firmware's clock is the first encoder frame's
timestamp plus 10 ms per tick; the log's own SIM_TRUTH frames are put back on the bus where the
log had them. Everything on the replayed bus is analysed as ``odocan run`` does
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
one firmware's poses at one frame agree). When the replay departs, the cause is
looked for by name (``diagnose``): the integrator the log's ODOM_STATUS reports against the one
replayed, and which robot profile (the one given and every shipped one) the logged poses fit
(``analyze`` of the log itself, no replay: the profile whose float64 odometry of the logged
counts the logged poses follow within tolerance).
"""

from __future__ import annotations

import itertools
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import can
import numpy as np
import numpy.typing as npt

from odocan.firmware.config import RobotParams
from odocan.firmware.errors import ErrorFlag
from odocan.host.io.listeners import Recording
from odocan.host.io.logs import (
    FrameArrays,
    FrameCollector,
    to_message,
)
from odocan.host.judge.analysis import HEADING_LSB_RAD, POSITION_LSB_M, Analysis, Tolerance, analyze
from odocan.host.judge.diagnosis import fitting_profiles
from odocan.host.judge.samples import Encoders, contract_cycle_s, named_targets
from odocan.host.outputs import OutputError
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e import check_frames
from odocan.host.stopped import Stopped, signum_of
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
MAX_GAP_TICKS = 6000  # a gap in the log longer than 60 s is replayed as 60 s
# One fresh in-process channel per replay, numbered (not id()-named) so two runs of the same
# command write the same bytes to --log.
_REPLAY_CHANNELS = itertools.count(1)


class ReplayError(OdocanError):
    """A log that cannot be replayed (no encoder frame, ...)."""


# --- what is fed -------------------------------------------------------------------------------


@dataclass(frozen=True)
class EncoderTrack:
    """The accepted WHEEL_ENCODERS frames of a FrameArrays and the tick of each."""

    index: IntArray  # positions in the frames
    counter: IntArray  # E2E COUNTER
    tick: IntArray  # 10 ms periods since the first one, strictly increasing
    timestamp_s: npt.NDArray[np.float64]  # bus times
    cycle_s: float | None  # the DBC cycle time

    @classmethod
    def of(cls, frames: FrameArrays, accepted: npt.NDArray[np.bool_],
           decoder: BulkDecoder) -> EncoderTrack:
        """The track of ``frames`` (empty when none is accepted)."""
        enc = decoder.decode(frames, "WHEEL_ENCODERS")
        keep = accepted[enc["index"]]
        counter = enc["COUNTER"][keep].astype(np.int64)
        ticks = encoder_ticks(enc["timestamp_s"][keep], counter)
        return cls(enc["index"][keep], counter, ticks, enc["timestamp_s"][keep],
                   contract_cycle_s(decoder, "WHEEL_ENCODERS"))

    def named(self, index: IntArray, enc_counter: IntArray,
              timestamp_s: npt.NDArray[np.float64]) -> IntArray:
        """The tick of the encoder frame that frames at ``index`` (sent at ``timestamp_s``)
        name by ``enc_counter``, resolved against the latest accepted encoder frame before each
        when it is less than 8 cycles older (``samples.named_targets``, the judges' rule: across
        a longer gap of the log the 4-bit COUNTER cannot tell the frame named from one 16
        periods away); -1 when that frame is not in the track."""
        result = np.full(len(index), -1, dtype=np.int64)
        if len(self.tick) == 0:
            return result
        none = np.zeros(len(self.tick), dtype=np.int64)
        as_encoders = Encoders(index=self.index, counter=self.counter, seq=self.tick, left=none,
                               right=none, timestamp_s=self.timestamp_s, cycle_s=self.cycle_s)
        has, target = named_targets(as_encoders, index, enc_counter, timestamp_s)
        target = target[has]
        found = np.minimum(np.searchsorted(self.tick, target), len(self.tick) - 1)
        result[has] = np.where(self.tick[found] == target, target, -1)
        return result


def encoder_ticks(timestamp_s: npt.NDArray[np.float64], counter: IntArray) -> IntArray:
    """The sender's period of each frame: COUNTER steps mod 16, widened by 16 where the
    timestamps say that many periods passed; gaps capped at ``MAX_GAP_TICKS``."""
    if len(counter) == 0:
        return np.zeros(0, dtype=np.int64)
    step = np.maximum(1, np.diff(counter) & 0xF).astype(np.int64)
    periods = np.rint(np.diff(timestamp_s) / contract.cycle_time_s("WHEEL_ENCODERS"))
    step += 16 * np.maximum(0, np.rint((periods - step) / 16)).astype(np.int64)
    step = np.minimum(step, MAX_GAP_TICKS)
    return np.concatenate(([0], np.cumsum(step))).astype(np.int64)


@dataclass(frozen=True)
class ReplayInput:
    """What a log gives the replay: the encoder frames to feed, and the SIM_TRUTH frames."""

    accepted: npt.NDArray[np.bool_]  # E2E verdict of every frame of the log
    encoders: EncoderTrack
    truth: IntArray  # positions of the SIM_TRUTH frames (all of them, as logged)
    rejected_encoders: int  # WHEEL_ENCODERS frames the E2E check dropped

    @classmethod
    def from_log(cls, frames: FrameArrays) -> ReplayInput:
        """Check the log's frames; ``ReplayError`` without an encoder frame to feed."""
        decoder = BulkDecoder(contract.database())
        _, accepted = check_frames(frames)
        encoders = EncoderTrack.of(frames, accepted, decoder)
        total = len(decoder.select(frames, "WHEEL_ENCODERS"))
        if total == 0:
            raise ReplayError("no WHEEL_ENCODERS frame (ID 0x100, 8 bytes) in the log: "
                              "nothing to feed the firmware")
        if len(encoders.index) == 0:
            raise ReplayError(f"none of the {total} WHEEL_ENCODERS frames passes its E2E check")
        truth = decoder.select(frames, "SIM_TRUTH").astype(np.int64)
        return cls(accepted, encoders, truth, total - len(encoders.index))


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
        self._buses = [can.Bus(interface="virtual", channel=channel, preserve_timestamps=True,
                               receive_own_messages=False) for _ in range(3)]
        self._log_bus, fw_bus, host_bus = self._buses
        self.board = FirmwareBoard(fw_bus, params, self.clock)
        self.listeners = listeners
        self.loop = TickLoop(self._work, host_bus, listeners, self.clock)
        self.stopped: Stopped | None = None  # by a signal, before the log's end

    @property
    def ticks(self) -> int:
        """Firmware ticks run so far."""
        return self.loop.ticks

    def _work(self, _k: int) -> None:
        """The nodes' work in a tick: the firmware's board alone (the log is the rest)."""
        self.board.run_tick()

    def run(self, frames: FrameArrays, feed: ReplayInput) -> None:
        """Feed every encoder frame at its tick (the log's truth frames where they were);
        Ctrl-C or SIGTERM stops it between two encoder frames, a second one at once
        (``stopped``: how far it got)."""
        enc = feed.encoders
        t0 = float(frames.timestamp_s[enc.index[0]])
        self.loop.start_s = t0
        events = _events(enc.index, feed.truth)
        due: int | None = None  # the tick whose encoder frame is on the bus, not yet run
        stop = StopRequest()
        interrupt: KeyboardInterrupt | None = None
        try:
            with stop_on_signals(stop):
                for position, which in events:
                    if which >= 0:  # an encoder frame: first run the ticks before its own
                        if stop.stop_requested:
                            break
                        tick = int(enc.tick[which])
                        if due is not None:
                            self.loop.run_to(tick)
                        self.clock.advance_to(t0 + tick * TICK_S)
                        due = tick
                    self._log_bus.send(to_message(frames, position))
                else:
                    if due is not None:
                        self.loop.run_to(due + 1)
        except KeyboardInterrupt as exc:
            interrupt = exc
        if stop.stop_requested or interrupt is not None:
            asked_s = (int(enc.tick[-1]) + 1) * TICK_S
            self.stopped = Stopped(stop.signum or signum_of(interrupt),
                                   round(self.ticks * TICK_S, 6), round(asked_s, 6))
            print(f"interrupted after {self.ticks * TICK_S:g} s of the log", file=sys.stderr)

    def _drain(self) -> None:
        deliver(self.loop.host_bus, self.listeners)

    def close(self) -> None:
        """Deliver what is left, stop the listeners, release the buses: every one, even when
        a listener's ``stop()`` fails (the first error is raised once all are released)."""
        release_all([self._drain, *(li.stop for li in self.listeners),
                     *(bus.shutdown for bus in self._buses)])


def _events(encoders: IntArray, truth: IntArray) -> list[tuple[int, int]]:
    """(position in the log, k) in log order: k the encoder frame's number, -1 for truth."""
    events = [(int(p), k) for k, p in enumerate(encoders.tolist())]
    events += [(int(p), -1) for p in truth.tolist()]
    events.sort()
    return events


# --- the replayed firmware against the logged one ----------------------------------------------


def onboard_by_tick(frames: FrameArrays, accepted: npt.NDArray[np.bool_]) -> dict[int, list[
        tuple[int, int, int]]]:
    """The on-board poses of ``frames`` by the tick of the encoder frame they name:
    (X raw, Y raw, heading in BAM16 units unwrapped = TURNS * 65536 + HEADING); the first X
    with the first Y, then each other X and Y sent naming it (a resend: every pose frame is
    compared, each half with the first of the other kind, as ``host.judge.resent``)."""
    decoder = BulkDecoder(contract.database())
    track = EncoderTrack.of(frames, accepted, decoder)
    halves = []
    for name, value, extra in (("ODOM_POSE_X", "X", "HEADING"), ("ODOM_POSE_Y", "Y", "TURNS")):
        d = decoder.decode(frames, name)
        keep = accepted[d["index"]]
        ticks = track.named(d["index"][keep], d["ENC_COUNTER"][keep].astype(np.int64),
                            d["timestamp_s"][keep])
        half: dict[int, list[tuple[int, int]]] = {}
        previous = -1  # a resend names its predecessor's frame (one naming an earlier one
        for tick, v, e in zip(ticks.tolist(), d[value][keep].tolist(), d[extra][keep].tolist(),
                              strict=True):  # after a gap of the log's frames is no resend)
            sent = half.setdefault(tick, []) if tick >= 0 else []
            if (not sent or tick == previous) and (int(v), int(e)) not in sent:
                sent.append((int(v), int(e)))
            previous = tick
        halves.append(half)
    px, py = halves
    return {t: [(x, py[t][0][0], py[t][0][1] * 65536 + h) for x, h in px[t]]
            + [(px[t][0][0], y, turns * 65536 + px[t][0][1]) for y, turns in py[t][1:]]
            for t in px.keys() & py.keys()}


def versus_log(
    log: FrameArrays, log_accepted: npt.NDArray[np.bool_], replayed: FrameArrays
) -> dict[str, Any]:
    """The replayed on-board poses against the logged ones at the same encoder frames (at each,
    the largest difference between any pose sent naming it in the log and in the replay)."""
    _, accepted = check_frames(replayed)
    old, new = onboard_by_tick(log, log_accepted), onboard_by_tick(replayed, accepted)
    common = sorted(old.keys() & new.keys())
    if not common:
        return {"samples": 0, "identical": 0, "max_position_diff_m": None,
                "max_heading_diff_rad": None, "before_first_gap": 0,
                "max_position_diff_before_gap_m": None,
                "max_resent_position_diff_m": resent_position_diff_m(old),
                "max_position_drift_between_gaps_m": None}
    pairs = [(t, a, b) for t in common for a, b in itertools.product(old[t], new[t])]
    at = np.searchsorted(np.array(common), [t for t, _, _ in pairs])
    a = np.array([p[1] for p in pairs], dtype=np.int64)
    b = np.array([p[2] for p in pairs], dtype=np.int64)
    position, heading, differs = (np.zeros(len(common)) for _ in range(3))
    np.maximum.at(position, at, np.hypot(a[:, 0] - b[:, 0], a[:, 1] - b[:, 1]) * POSITION_LSB_M)
    np.maximum.at(heading, at, np.abs(a[:, 2] - b[:, 2]) * HEADING_LSB_RAD)
    np.maximum.at(differs, at, (a != b).any(axis=1).astype(np.float64))
    ticks = EncoderTrack.of(log, log_accepted, BulkDecoder(contract.database())).tick
    gaps = np.flatnonzero(np.diff(ticks) > 1)
    first_gap = int(ticks[gaps[0]]) if len(gaps) else int(ticks[-1])  # last tick before it
    before = int(np.searchsorted(np.array(common), first_gap, side="right"))
    first = np.array([(old[t][0][0] - new[t][0][0], old[t][0][1] - new[t][0][1])
                      for t in common], dtype=np.int64)
    return {
        "samples": len(common),
        "identical": int(np.count_nonzero(differs == 0)),
        "max_position_diff_m": float(position.max()),
        "max_heading_diff_rad": float(heading.max()),
        "before_first_gap": before,
        "max_position_diff_before_gap_m": float(position[:before].max()) if before else None,
        "max_resent_position_diff_m": resent_position_diff_m(old),
        "max_position_drift_between_gaps_m": drift_between_gaps_m(
            np.array(common), first, ticks[gaps + 1]) if replayable(log, log_accepted) else None,
    }


def replayable(frames: FrameArrays, accepted: npt.NDArray[np.bool_]) -> bool:
    """True when the recording firmware took exactly the log's accepted encoder frames, each on
    its tick, as far as the log tells: no ODOM_STATUS summary reports TIME_LOST or
    MAILBOX_OVERFLOW (frames merged on board) and the host's E2E check refused no encoder frame
    (a late one the firmware may have taken). Else a drift between gaps is no departure."""
    encoders = frames.can_id == contract.database().get_message_by_name("WHEEL_ENCODERS").frame_id
    if (encoders & ~accepted).any():
        return False
    try:
        page = BulkDecoder(contract.database()).decode_page(frames, "ODOM_STATUS", 0)
    except DecodeError:
        return True
    masks = page["ERROR_MASK"][accepted[page["index"]]].astype(np.int64)
    return not (masks & (ErrorFlag.TIME_LOST | ErrorFlag.MAILBOX_OVERFLOW)).any()


def drift_between_gaps_m(
    common: npt.NDArray[np.int64], offset: npt.NDArray[np.int64], gap_ends: npt.NDArray[np.int64]
) -> float:
    """How far the logged and the replayed positions move apart between two gaps of the log's
    encoder sequence after its first (m; before it they are compared as they are): ``offset``
    (log - replay, raw LSB, at the ``common`` ticks) less its value at the first common tick of
    its segment (``gap_ends``: the first tick after each gap), less one LSB per axis. Across a
    gap the recording firmware may have had frames the log lacks, so the offset may jump there;
    between gaps both firmwares take the same frames from the same heading (exact everywhere),
    so one firmware's offset stays put: on the bus, rounded to the LSB, within one LSB per axis
    of it."""
    if len(common) == 0:
        return 0.0
    segment = np.searchsorted(gap_ends, common, side="right")
    first = np.r_[True, segment[1:] != segment[:-1]]  # a segment's first common tick
    anchor = offset[np.flatnonzero(first)][np.cumsum(first) - 1]
    moved = np.maximum(np.abs(offset - anchor) - 1, 0)[segment > 0]
    return float(np.hypot(moved[:, 0], moved[:, 1]).max(initial=0.0)) * POSITION_LSB_M


def resent_position_diff_m(poses: dict[int, list[tuple[int, int, int]]]) -> float:
    """The largest position difference between a pose resent naming an encoder frame and the
    first naming it, in one log (``onboard_by_tick``): across a gap the log's positions are not
    compared with the replay's, but one firmware's poses at one frame must agree anyway."""
    diff = [math.hypot(x - sent[0][0], y - sent[0][1])
            for sent in poses.values() for x, y, _ in sent[1:]]
    return max(diff, default=0.0) * POSITION_LSB_M


def departures(vs_log: dict[str, Any], tolerance: Tolerance) -> list[str]:
    """Why the replayed firmware departs from the recorded one (module docstring, "Verdict"):
    empty when it does not (or when the log has no on-board pose to compare with)."""
    reasons = []
    position = vs_log["max_position_diff_before_gap_m"]
    if position is not None and position > tolerance.position_m:
        reasons.append(f"its position differs from the log's by up to {position * 1e3:.4f} mm "
                       f"(tolerance {tolerance.position_m * 1e3:.4g} mm)")
    drift = vs_log.get("max_position_drift_between_gaps_m")
    if drift is not None and drift > tolerance.position_m:
        reasons.append(f"between gaps of the log its position moves off the log's by up to "
                       f"{drift * 1e3:.4f} mm (tolerance {tolerance.position_m * 1e3:.4g} mm)")
    resent = vs_log.get("max_resent_position_diff_m")
    if resent is not None and resent > tolerance.position_m:
        reasons.append(f"the log's resent positions differ from its first at the same encoder "
                       f"frame by up to {resent * 1e3:.4f} mm "
                       f"(tolerance {tolerance.position_m * 1e3:.4g} mm)")
    heading = vs_log["max_heading_diff_rad"]
    if heading is not None and heading > tolerance.heading_rad:
        reasons.append(f"its heading differs from the log's by up to {heading * 1e3:.4f} mrad "
                       f"(tolerance {tolerance.heading_rad * 1e3:.4g} mrad)")
    return reasons


def diagnose(
    log: FrameArrays, accepted: npt.NDArray[np.bool_], profile: RobotProfile, integrator: str,
    tolerance: Tolerance, *, source: str = "LOG", robot_arg: str | None = None,
) -> list[str]:
    """The likely cause of a departure, by name: an integrator other than the log's, a robot
    profile other than the one the logged poses fit (module docstring, "Verdict"); when none
    fits, either the profile or the recording firmware (``source``: the log's name, and
    ``robot_arg``: the --robot given, for the command that says which poses are off)."""
    reasons = []
    logged = logged_integrator(log, accepted)
    if logged is not None and logged != integrator:
        reasons.append(f"integrator mismatch: the log's ODOM_STATUS reports {logged}, the replay "
                       f"ran {integrator}")
    fits = fitting_profiles(log, profile, logged or integrator, tolerance)
    if profile.name in fits:
        if logged is None or logged == integrator:
            lived = unreplayable(analyze(log, profile, integrator, tolerance=tolerance).report)
            reasons.append(f"the log fits robot {profile.name!r} with the {integrator} "
                           + ("integrator, but its firmware lived what a lockstep replay does "
                              f"not reproduce: {'; '.join(lived)}" if lived else
                              "integrator: the firmware build differs from the one that "
                              "recorded it"))
    elif fits:
        reasons.append(f"robot mismatch: the log's poses fit robot {', '.join(map(repr, fits))}, "
                       f"not {profile.name!r} (--robot)")
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


def replay_and_analyze(
    frames: FrameArrays, feed: ReplayInput, profile: RobotProfile, integrator: str, *,
    tolerance: Tolerance, log: Path, log_out: Path | None = None,
) -> Analysis:
    """Run the replay (every frame it puts on its bus written to ``log_out`` when given),
    analyse the replayed bus, add the ``replay`` section."""
    collector = FrameCollector()
    listeners: list[can.Listener] = [collector]
    if log_out is not None:  # a full disk stops the recording, not the replay (path named)
        listeners.append(Recording(can.Logger(log_out)))
    channel = f"odocan-replay-{next(_REPLAY_CHANNELS)}"
    replay = LockstepReplay(firmware_params(profile, integrator), listeners, channel)
    start = time.perf_counter()
    try:
        replay.run(frames, feed)
    finally:
        try:
            replay.close()
        except OSError as exc:
            raise OutputError(f"--log {log_out}: {exc.strerror or exc}") from None
    wall_s = time.perf_counter() - start
    replayed = collector.arrays()
    analysis = analyze(replayed, profile, integrator, tolerance=tolerance,
                       wall_seconds=wall_s)
    analysis.report["replay"] = {
        "log": str(log),
        "encoder_frames_fed": len(feed.encoders.index),
        "encoder_frames_rejected": feed.rejected_encoders,
        "truth_frames": len(feed.truth),
        "ticks": replay.ticks,
        "ticks_without_frame": replay.ticks - min(replay.ticks, len(feed.encoders.index)),
        "interrupted": replay.stopped is not None,
        "onboard_vs_log": versus_log(frames, feed.accepted, replayed),
    }
    if replay.stopped is not None:
        analysis.report["stopped"] = replay.stopped.as_dict()
    return analysis


