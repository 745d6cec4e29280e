"""Firmware reboots inside a log: where each firmware life starts, and one report of them all.

A reboot is told the way the live monitor tells it (``host.judge.sources.SourceWatch``, the one
detection): the ODOM_STATUS summaries whose CRC holds, whatever their E2E sequence (a new
firmware restarts its counters), fed in bus order; a ``"reboot"`` is UPTIME going back, INIT
after running, or (in the first second of uptime) the power-up tick's E2E COUNTERs
(``host.judge.bootticks``). The frame of that summary is the new firmware's first (its tick 0
sends a summary, firmware/ecu.py).

The new firmware's pose is (0, 0, 0) at the first encoder frame it accepted (it primes there),
so each life is analysed on its own, its reference restarted from that power-up pose at that
frame (``Life.boot``), with E2E sequences starting afresh (a reboot is not frames lost):

* the boot summary says UPTIME 0 and STATE INIT: the firmware had no encoder frame yet; it
  primes on the first WHEEL_ENCODERS frame after the summary;
* UPTIME 0 and any other state: it accepted one in its first tick, the latest WHEEL_ENCODERS
  frame before the summary; the life starts at that frame (the first tick's pose frames come
  before its summary, firmware/ecu.py step 5; a frame the old firmware sent after it would be
  taken for the new one's);
* UPTIME above 0 (the recorder missed the boot summary): where it primed is unknown; the life
  starts at the summary and its start is fitted like a log that starts mid-drive;
* whatever the summary says, when the new firmware's first page of WHEEL_ENCODERS E2E counts
  (ENC_E2E_OK: encoder frames accepted since its boot; ENC_E2E_LOST: lost) follows, it names
  the frame it primed on: ENC_E2E_OK + ENC_E2E_LOST - 1 COUNTER steps back from the latest
  encoder frame before the page was sent (``page_counted_start``: the earliest the counts allow;
  a page the bus held back, in order, is counted from its send, ``host.judge.pagesent``: from
  its stamp, figure8 672's new life started 5 frames late and FAILed by 634 mm). That holds when the
  log missed the boot summary (UPTIME counts whole seconds: the summaries of the first second
  all say 0) and is checked again on the life (``host.judge.powerup.saw_only_the_log``); that
  life is a power-up (``Life.boot``) whatever UPTIME says: a new firmware starts at (0, 0, 0)
  (issue #11: rebooted inside a 2 s bus-off, UPTIME 1 in the first summary heard, its start was
  fitted and a firmware 10 mm off over the whole new life PASSed);
* above both, when the summary (UPTIME 0) follows the new firmware's power-up pose within 80 ms,
  the frame that pose names (``host.judge.bootnamed``): the two rules above read ODOM_STATUS
  stamps, which a recorder may have delayed (every one 15..50 ms late: 1..5 frames late);
  not when the first pose after the summary does not count on from it (the bus lost the new
  power-up pose: the one named was the old firmware's, ``bootnamed.first_after``).
* except when the new firmware stalled before its first count page (``stalled_first``: before
  its first pose or after it): that page misses the frames its halted MCU's FIFO overran, so
  the summary's rule stands.

A life with no on-board sample (a reboot at the very end) is reported, not compared.

Without that page (other firmwares need not send it) and without the power-up pose, a reboot
whose first summary heard ends a silence of the firmware starts after the old firmware's last
frame and is judged from (0, 0, 0) on each frame it may have primed on (``silentboot``); else
the life starts at that summary's frame (known limit: a reboot missed without a silence).

Each new life has its own origin, so its pose is compared with the truth in that frame: the
truth re-based at the life's power-up frame (``host.judge.compare.life_origin``, the same in the
streamed and the live judges), reported per reboot as ``truth_origin`` (None: no truth sample
in the life). The log's first life is compared in the truth's own frame: its firmware came up
with the simulator (a log that starts mid-drive has its reference start fitted, its truth kept).

``merge`` makes one report and one set of series of the lives' (``host.judge.analysis``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.bootnamed import heard_encoders, named_start, pose_enc_rows, powerup_poses
from odocan.host.judge.bootsummaries import boot_summaries as boot_summaries
from odocan.host.judge.bootsummaries import two_sources as two_sources
from odocan.host.judge.bootticks import TWIST_COUNTERS, fell_in_run
from odocan.host.judge.breaks import merged_breaks
from odocan.host.judge.gapseen import crc_holds
from odocan.host.judge.heldboot import held_start, held_ticks
from odocan.host.judge.heldboot import summary_start as summary_start
from odocan.host.judge.heldtick import tick_pages, told_tick
from odocan.host.judge.heldtick import tick_s as page_tick_s
from odocan.host.judge.liveconfig import config_text
from odocan.host.judge.navrestart import second_evidence
from odocan.host.judge.pagesent import encoder_count_pages as encoder_count_pages
from odocan.host.judge.pagesent import pages_counted_from
from odocan.host.judge.primed import counted_start
from odocan.host.judge.samples import AnalysisError, contract_cycle_s
from odocan.host.judge.silentboot import fresh_counted_start, silent_start
from odocan.host.judge.sources import two_sources_text
from odocan.host.judge.stallfirst import merged_first
from odocan.host.judge.stalls import silent_between
from odocan.host.protocol import busfacts
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import check_frames

ENC_MASK = busfacts.ENC_COUNTER_MASK
SUMMARY_PAGE = busfacts.SUMMARY_PAGE  # ODOM_STATUS page with STATE and UPTIME


@dataclass(frozen=True)
class Life:
    """The frames of one firmware life: positions in the log, in bus order."""

    index: npt.NDArray[np.int64]
    boot: bool  # starts at the firmware's power-up (pose 0 at its first encoder frame)
    t_s: float | None = None  # bus time of the boot summary (None: the log's first life)
    uptime_before_s: int | None = None  # the last UPTIME the previous firmware reported
    set_pose: Any = None  # a set-pose's life (``host.judge.setposes.SetPoseCut``), not a reboot
    config: Any = None  # an applied config's life (``host.judge.configs.ConfigCut``), no reboot
    silent: bool = False  # primed in a silence on a frame nothing names (``silentboot``)


def split_lives(frames: FrameArrays, decoder: BulkDecoder) -> list[Life]:
    """The log cut at every reboot (module docstring); one life when there is none."""
    everything = np.arange(len(frames), dtype=np.int64)
    boots = boot_summaries(frames, decoder)
    if not boots:
        return [Life(everything, boot=False)]
    _, accepted = check_frames(frames, decoder.db)  # the encoder frames a firmware takes
    rows = decoder.decode(frames, "WHEEL_ENCODERS")
    keep = accepted[rows["index"]]
    encoders, counters = rows["index"][keep], rows["COUNTER"][keep].astype(np.int64)
    pages, every = encoder_count_pages(frames, decoder), (frames.select(rows["index"]),
                                                          rows["index"].astype(np.int64))
    sent = pages_counted_from(frames, decoder, pages[0], (encoders.astype(np.int64), counters))
    poses, after = powerup_poses(frames, decoder), pose_enc_rows(frames, decoder)
    heard = heard_encoders(every, decoder)  # the power-up pose's word (``bootnamed``)
    starts: list[int] = []
    counted_boots: list[bool] = []  # the start named by the new firmware's first count page
    silent: list[bool] = []  # primed in a silence on a frame nothing names (``silentboot``)
    limits = [b[0] for b in boots[1:]] + [len(frames)]
    for (position, uptime_s, state, _), limit, tick_s in zip(
            boots, limits, _ticks(frames, decoder, [b[0] for b in boots]), strict=True):
        start = (summary_start(position, uptime_s, state, encoders) if tick_s is None else
                 held_start(position, uptime_s, state, (every[1], frames.timestamp_s[every[1]]),
                            tick_s, every[0].data[:, 1].astype(np.int64) & ENC_MASK))
        counted = (None if stalled_first(frames, decoder, encoders, position, limit)
                   else page_counted_start(position, limit, (encoders, counters), pages, (
                       every, decoder, (starts[-1] if starts else 0,
                                        summary_start(position, uptime_s, state, rows["index"]))),
                       sent))
        said = (named_start(poses, (encoders.astype(np.int64), counters), position,
                            float(frames.timestamp_s[position]), after, heard)
                if uptime_s == 0 else None)
        named = None if said is None else said[0]
        for found in (counted if tick_s is None else None, named):  # the pose's word last
            if found is not None and found > (starts[-1] if starts else 0):
                start = found
        quiet = (None if counted is not None or named is not None else silent_start(
            frames, decoder, encoders, position, starts[-1] if starts else 0))
        silent.append(quiet is not None)
        starts.append(start if quiet is None else quiet)
        counted_boots.append(counted is not None and start == counted)
    lives = [Life(everything[: starts[0]], boot=False)]
    for k, (position, uptime_s, _, before_s) in enumerate(boots):
        end = starts[k + 1] if k + 1 < len(starts) else len(frames)
        lives.append(Life(everything[starts[k] : end], boot=uptime_s == 0 or counted_boots[k],
                          t_s=float(frames.timestamp_s[position]), uptime_before_s=before_s,
                          silent=silent[k]))
    return lives


def _ticks(frames: FrameArrays, decoder: BulkDecoder, positions: list[int]) -> list[float | None]:
    """Per boot summary at ``positions``: the bus time of its tick when the bus held it back
    behind its tick's page (``heldboot.held_ticks``: right behind it; else ``heldtick``: past
    the next summary), None when it was not."""
    falls = second_evidence(frames, decoder, TWIST_COUNTERS)[0]  # ``bootsummaries``' own
    pages = [told_tick(page, lambda page_s: fell_in_run(falls, page_s)) for page in
             tick_pages(frames, decoder, np.array(positions, dtype=np.int64))]
    return [page_tick_s(held, page)
            for held, page in zip(held_ticks(frames, decoder, positions), pages, strict=True)]


def stalled_first(frames: FrameArrays, decoder: BulkDecoder, encoders: npt.NDArray[np.intp],
                  position: int, limit: int) -> bool:
    """Whether the firmware booted by the summary at ``position`` stalled before its first page
    of E2E counts (before its first pose or after it): ``stalls.silent_between`` on its
    ODOM_STATUS frames whose CRC holds and its ODOM_POSE_Y from the summary to that page or its
    first pose, the later (``told_by``), while the encoder frames, accepted at ``encoders``,
    went on on time. A stalled MCU's receive FIFO overran frames it never counted, so that page
    cannot name the frame it primed on (``counted_start`` lands hundreds of frames late); its
    summary's rule stands. Issue #11: reset with its FIFO cleared, halted 600 ticks from 2
    ticks after (one pose before the stall), the life started 593 frames late and the correct
    firmware FAILed by 42 mm."""
    ys = decoder.select(frames, "ODOM_POSE_Y")
    ys = ys[(ys > position) & (ys < limit)]
    if not len(ys):
        return False  # no pose in its life: nothing to judge from its start
    stop = told_by(position, limit, encoder_count_pages(frames, decoder)[0], ys)
    status = decoder.select(frames, "ODOM_STATUS")
    status = status[(status >= position) & (status <= stop)]
    alive = np.sort(np.concatenate((status[crc_holds(frames, decoder, status)],
                                    ys[ys <= stop])))
    return silent_between(frames.timestamp_s[alive], frames.timestamp_s[encoders],
                          contract_cycle_s(decoder, "WHEEL_ENCODERS"))


def told_by(position: int, limit: int, pages: npt.NDArray[np.int64],
            ys: npt.NDArray[np.intp]) -> int:
    """Up to where a stall tells the life booted at ``position`` (``stalled_first``): its first
    count page or its first pose (ODOM_POSE_Y ``ys``), the later (a stall before the first pose
    after a page of its first tick still does), else ``limit`` (the next boot)."""
    paged = pages[(pages > position) & (pages < limit)]
    if not len(paged) or not len(ys):
        return limit
    return max(int(paged[0]), int(ys[0]))


def page_counted_start(
    position: int, limit: int, encoders: tuple[npt.NDArray[np.intp], npt.NDArray[np.int64]],
    pages: tuple[npt.NDArray[np.int64], ...],
    fresh: tuple[tuple[FrameArrays, npt.NDArray[np.int64]], BulkDecoder, tuple[int, int]]
    | None = None, sent: npt.NDArray[np.int64] | None = None,
) -> int | None:
    """The encoder frame the firmware primed on, from its first page of WHEEL_ENCODERS E2E
    counts after the summary at ``position`` (and before ``limit``, the next boot):
    ``counted_start``; with ``fresh`` (every WHEEL_ENCODERS frame and its position, the
    decoder, the life before's start and ``summary_start`` over every WHEEL_ENCODERS frame),
    its E2E check fresh at that frame as the new firmware's was
    (``silentboot.fresh_counted_start``); with ``sent`` (per page, the position it is counted
    from: ``pagesent.pages_counted_from``), counted from where it was sent, not heard. None
    without such a page."""
    where, ok, lost = pages
    after = int(np.searchsorted(where, position))
    if after == len(where) or where[after] >= limit:
        return None
    page = int(where[after] if sent is None else sent[after])
    counts = (int(ok[after]), int(lost[after]))
    counted = counted_start(encoders, page, *counts)
    return counted if fresh is None else fresh_counted_start(
        fresh[0], fresh[1], page, counts, (counted, fresh[2][1], fresh[2][0]))




def before_two_sources(frames: FrameArrays, decoder: BulkDecoder,
                       conflict: tuple[int, float]) -> int:
    """Where the frames of one firmware end (``two_sources``): the start of the life the second
    firmware's first summary was taken to begin (its first pose frames come before that
    summary), else that summary. Raises ``AnalysisError`` when no frame comes before it."""
    position, t_s = conflict
    starts = [int(life.index[0]) for life in split_lives(frames, decoder)
              if life.t_s == t_s and len(life.index)]
    cut = min([position, *starts])
    if cut == 0:
        raise AnalysisError(f"{two_sources_text(t_s)}, from the log's start")
    return cut


def mark_two_sources(report: dict[str, Any], t_s: float, frames_not_judged: int,
                     detail: str | None = None) -> None:
    """A FAIL of its own in ``report`` (``two_sources``, an event): from ``t_s`` two firmwares
    answered on one node ID. Their pose frames interleave with nothing to tell whose each is,
    so no pose from there is judged (a pose error there would blame a firmware that may be
    right); what came before is judged as usual, and a wrong pose there fails as well.
    ``detail``: the reason (``two_sources_text`` when None: told by UPTIME)."""
    detail = detail or two_sources_text(t_s)
    report["two_sources"] = {"t_s": t_s, "frames_not_judged": frames_not_judged,
                             "detail": detail}
    report["events"] = sorted([*report["events"], {"kind": "two sources", "t_s": t_s,
                                                    "detail": detail}], key=lambda e: e["t_s"])
    report["passed"] = False




# --- one report of the lives ----------------------------------------------------------------

_SUMMED_SAMPLES = ("onboard", "truth", "truth_compared", "unmatched_poses", "encoder_frames",
                   "reference_restarts", "implausible_encoder_frames", "stall_first_judged",
                   "stall_first_unjudged", "stall_first_unmatched", "lone_halves_judged",
                   "lone_halves_unjudged", "unmatched_sent", "names_ahead_judged",
                   "names_ahead_unjudged")
_TIME_SERIES = ("t_s", "truth_t_s", "gap_start_t_s", "gap_end_t_s", "restart_t_s")


def merge(
    reports: list[dict[str, Any]],
    series: list[dict[str, np.ndarray]],
    lives: list[Life],
    t_first_s: list[float],
    *,
    silent: list[Life] | None = None,
) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """One report and one set of series from those of the lives with samples (``lives``,
    ``t_first_s``: each one's, in order; the first of them is the whole log's origin); the
    reboots of the ``silent`` lives (no on-board sample) are reported with 0 samples."""
    report = dict(reports[0])
    last = reports[-1]
    report["samples"] = {key: sum(r["samples"].get(key, 0) for r in reports)
                         for key in _SUMMED_SAMPLES}
    report["onboard_vs_reference"] = _worst([r["onboard_vs_reference"] for r in reports])
    report["reference_breaks"] = merged_breaks([r["reference_breaks"] for r in reports])
    report["stall_first_pose"] = merged_first([r.get("stall_first_pose") for r in reports])
    truths = [r["onboard_vs_truth"] for r in reports]
    report["onboard_vs_truth"] = _worst(truths)
    report["onboard_vs_truth"]["distance_travelled_m"] = float(
        sum(t["distance_travelled_m"] for t in truths))
    report["onboard_twist_vs_reference"] = _twist(
        [r["onboard_twist_vs_reference"] for r in reports])
    report["onboard_distance_vs_reference"] = _distance(
        [r["onboard_distance_vs_reference"] for r in reports])
    report["final_onboard_pose"] = last["final_onboard_pose"]
    report["e2e"] = _summed_counts([r["e2e"] for r in reports])
    report["unknown_frames"] = _summed_counts([{"u": r["unknown_frames"]} for r in reports])["u"]
    events = [dict(e, life=k) for k, r in enumerate(reports) for e in r["events"]]
    report["firmware_events"] = [dict(e, life=k) for k, r in enumerate(reports)
                                 for e in r.get("firmware_events", [])]
    report["firmware_final"] = last.get("firmware_final")  # the last firmware's state
    report.pop("truth_origin", None)
    reboots = [
        {"t_s": life.t_s, "uptime_before_s": life.uptime_before_s,
         "reference_start": r["reference_start"], "onboard_samples": r["samples"]["onboard"],
         "life": k, "truth_origin": r.get("truth_origin")}
        for k, (life, r) in enumerate(zip(lives, reports, strict=True))
        if life.t_s is not None and life.set_pose is None and life.config is None
    ] + [
        {"t_s": life.t_s, "uptime_before_s": life.uptime_before_s, "reference_start": None,
         "onboard_samples": 0, "life": None, "truth_origin": None}
        for life in silent or []
        if life.t_s is not None and life.set_pose is None and life.config is None
    ]
    events += [set_pose_event(life, k, r) for k, (life, r)
               in enumerate(zip(lives, reports, strict=True)) if life.set_pose is not None]
    events += [config_event(life, k, r) for k, (life, r)
               in enumerate(zip(lives, reports, strict=True)) if life.config is not None]
    reboots.sort(key=lambda b: b["t_s"])
    events += [
        {"kind": "reboot", "t_s": b["t_s"], "life": b["life"],
         "detail": f"the firmware restarted (UPTIME {b['uptime_before_s']} s -> 0): "
                   + (f"the reference restarts from its {b['reference_start']} pose"
                      if b["reference_start"] else "no on-board pose after it to compare")
                   + (", the truth is compared in the new life's frame (truth_origin)"
                      if b["truth_origin"] else "")}
        for b in reboots
    ]
    report["events"] = sorted(events, key=lambda e: e["t_s"])
    report["reboots"] = reboots
    return report, _joined(series, reports, t_first_s)


def _worst(parts: list[dict[str, Any]]) -> dict[str, Any]:
    """Max errors over the lives, final errors of the last one with a sample."""
    known = [p for p in parts if p["max_position_error_m"] is not None]
    if not known:
        return dict(parts[-1])
    worst = {
        "max_position_error_m": max(p["max_position_error_m"] for p in known),
        "max_heading_error_rad": max(p["max_heading_error_rad"] for p in known),
        "final_position_error_m": known[-1]["final_position_error_m"],
        "final_heading_error_rad": known[-1]["final_heading_error_rad"],
    }
    beyond = "max_position_error_beyond_allowance_m"  # kept over the lives (summary, tests)
    if any(beyond in p for p in known):  # a life without an allowance: its whole error
        worst["loss_allowance_m"] = max(p.get("loss_allowance_m", 0.0) for p in known)
        worst[beyond] = max(p.get(beyond, p["max_position_error_m"]) for p in known)
    return worst


def _twist(parts: list[dict[str, Any]]) -> dict[str, Any]:
    return {
        "samples": sum(p["samples"] for p in parts),
        "max_linear_excess_mps": max(p["max_linear_excess_mps"] for p in parts),
        "max_angular_excess_rad_s": max(p["max_angular_excess_rad_s"] for p in parts),
        "passed": all(p["passed"] for p in parts),
    }


def _distance(parts: list[dict[str, Any]]) -> dict[str, Any]:
    """Each life judged from its own start (a reboot restarts the firmware's DISTANCE)."""
    return {
        "samples": sum(p["samples"] for p in parts),
        "start": parts[0]["start"] if parts else "fitted",
        "max_excess_m": max((p["max_excess_m"] for p in parts), default=0.0),
        "passed": all(p["passed"] for p in parts),
    }


def _summed_counts(parts: list[dict[str, dict[str, int]]]) -> dict[str, dict[str, int]]:
    """Counts per message summed over the lives (E2E sequences start afresh at a reboot)."""
    total: dict[str, dict[str, int]] = {}
    for part in parts:
        for name, counts in part.items():
            into = total.setdefault(name, dict.fromkeys(counts, 0))
            for key, value in counts.items():
                into[key] = into.get(key, 0) + value
    return total


def _joined(
    series: list[dict[str, np.ndarray]], reports: list[dict[str, Any]], t_first_s: list[float]
) -> dict[str, np.ndarray]:
    """The lives' series one after the other: times since the log's first frame, distances
    along the reference carried on from one life to the next."""
    distance = time = 0.0
    pieces: dict[str, list[np.ndarray]] = {}
    for k, part in enumerate(series):
        time = t_first_s[k] - t_first_s[0]
        for key, values in part.items():
            if key.endswith("distance_m"):
                values = values + distance
            elif key in _TIME_SERIES:
                values = values + time
            pieces.setdefault(key, []).append(values)
        distance += float(reports[k]["onboard_vs_truth"]["distance_travelled_m"])
    return {key: np.concatenate(values) for key, values in pieces.items()}


def set_pose_event(life: Life, k: int, report: dict[str, Any]) -> dict[str, Any]:
    """The ``set_pose`` event of a set-pose's life (``host.judge.setposes``): its time, the
    fields set (None: kept by the firmware), how its reference started."""
    staged = life.set_pose.staged
    start = report["reference_start"]
    return {"kind": "set_pose", "t_s": life.t_s, "life": k, "x_m": staged.get("X"),
            "y_m": staged.get("Y"), "heading_rad": staged.get("HEADING"),
            "truth_origin": report.get("truth_origin"),
            "detail": "set pose applied: the reference restarts "
                      + ("at the pose set" if start == "set pose" else
                         f"from a {start} start (not every field was set)")
                      + ", the truth is compared in the new frame (truth_origin)"}


def config_event(life: Life, k: int, report: dict[str, Any]) -> dict[str, Any]:
    """The ``config`` event of an applied config's life (``host.judge.configs``): its time (the
    ACK's), the parameters applied, the monitor's words with the robot the life was judged with."""
    robot = report["robot"]
    return {"kind": "config", "t_s": life.t_s, "life": k, "parameters": dict(life.config.staged),
            "detail": config_text(robot["counts_per_rev"], robot["wheel_radius_left_m"],
                                  robot["wheel_radius_right_m"], robot["wheelbase_m"],
                                  report["integrator"])}
