"""Which ODOM_STATUS summaries of a whole log start a new firmware, and where two firmwares
began to answer on one node ID: one pass of ``host.judge.sources.SourceWatch`` over the
summaries (the rule of every judge), for ``host.judge.reboots`` (split from it: its size)."""

from __future__ import annotations

import numpy as np

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.aheadticks import ahead_ticks
from odocan.host.judge.bootticks import (
    TWIST_COUNTERS,
    boot_ticks,
    fell_in_run,
    poses_before,
    status_before,
)
from odocan.host.judge.gapseen import crc_holds
from odocan.host.judge.heldsummaries import held_evidence, summaries_held_back
from odocan.host.judge.heldtick import tick_pages, told_tick
from odocan.host.judge.navrestart import second_evidence
from odocan.host.judge.sources import SourceWatch
from odocan.host.protocol import busfacts
from odocan.host.protocol.decode import BulkDecoder, DecodeError

SUMMARY_PAGE = busfacts.SUMMARY_PAGE  # ODOM_STATUS page with STATE and UPTIME
_FIRST_WINDOW = 64  # summaries tried at once after one that was not quiet (doubles while quiet)


def two_sources(frames: FrameArrays, decoder: BulkDecoder) -> tuple[int, float] | None:
    """Where two firmwares began to answer on one node ID (``SourceWatch``: two UPTIME offsets
    interleave): (position, bus time) of the summary that brought the second offset; None when
    the log has one source at a time."""
    return _watch_summaries(frames, decoder)[1]


def boot_summaries(frames: FrameArrays, decoder: BulkDecoder) -> list[tuple[int, int, str, int]]:
    """(position, UPTIME s, STATE, previous UPTIME s) of each summary that starts a new
    firmware (module docstring)."""
    return _watch_summaries(frames, decoder)[0]


def _watch_summaries(
    frames: FrameArrays, decoder: BulkDecoder
) -> tuple[list[tuple[int, int, str, int]], tuple[int, float] | None]:
    """``boot_summaries`` and ``two_sources`` from one pass of ``SourceWatch``."""
    try:
        page = decoder.decode_page(frames, "ODOM_STATUS", SUMMARY_PAGE)
        message = decoder.message("ODOM_STATUS")
    except DecodeError:
        return [], None
    if "UPTIME" not in page or "STATE" not in page or len(page["index"]) == 0:
        return [], None
    index = page["index"]
    good = crc_holds(frames, decoder, index)
    choices = dict(message.get_signal_by_name("STATE").choices or {})
    codes, which = np.unique(page["STATE"][good], return_inverse=True)
    names = [str(choices.get(int(code), int(code))) for code in codes.tolist()]
    states = np.array(names, dtype=object)[which]
    positions, times_s = index[good], page["timestamp_s"][good]
    uptimes_s = page["UPTIME"][good].astype(np.int64)
    counters = page["COUNTER"][good].astype(np.int64)
    poses = poses_before(frames, decoder, positions)[0]  # their ticks' (``bootticks``)
    statuses = status_before(frames, decoder, positions)[0]
    falls = second_evidence(frames, decoder, TWIST_COUNTERS)[0]  # DISTANCE fell, NAV restarted
    booted = boot_ticks(uptimes_s, counters, times_s, poses, statuses, None, falls)
    ahead = ahead_ticks(frames, decoder, positions, uptimes_s, counters, times_s, statuses)
    late = summaries_held_back(frames, decoder, (positions, uptimes_s, states))
    held = held_evidence(frames, decoder, positions, bool(booted.any()))
    zeros = (uptimes_s == 0) & (counters == 0)  # a boot summary held past its tick's page
    ticks = tick_pages(frames, decoder, positions) if zeros.any() else [None] * len(positions)
    ticked = np.array([t is not None for t in ticks], dtype=bool)
    watch = SourceWatch()
    boots = []
    changed, conflict = 0, None  # the summary of the last new offset; where two sources began
    k, window = 0, _FIRST_WINDOW
    while k < len(positions):  # quiet stretches at once (observe_quiet), the others one by one
        end = min(len(positions), k + window)
        k += watch.observe_quiet(
            times_s[k:end],
            uptimes_s[k:end],
            states[k:end],
            booted[k:end] | ahead[k:end] | ticked[k:end],
        )
        if k == end:
            window *= 2
            continue
        window = _FIRST_WINDOW
        before = watch.last_uptime_s
        name = str(states[k])
        pose_counter = int(poses[1][k])
        watch.pose = (
            None if pose_counter < 0 else (float(poses[0][k]), pose_counter, bool(poses[2][k]))
        )
        status_counter = int(statuses[1][k])
        watch.status_before = (
            None if status_counter < 0 else (float(statuses[0][k]), status_counter)
        )
        tick = watch.ticks.told = told_tick(ticks[k], lambda page_s: fell_in_run(falls, page_s))
        watch.ticks.fell = tick is not None  # (``heldtick``)
        kind = watch.observe(
            float(times_s[k]),
            int(uptimes_s[k]),
            name,
            int(counters[k]),
            bool(ahead[k]),
            fell=fell_in_run(falls, float(times_s[k])),
            late=bool(late[k]),
            held=(bool(held[k, 0]), bool(held[k, 1])),
        )
        if kind == "reboot":
            boots.append((int(positions[k]), int(uptimes_s[k]), name, int(before)))
        if watch.changed_at_s == float(times_s[k]):
            changed = k
        if kind == "two sources" and conflict is None:
            conflict = (int(positions[changed]), float(times_s[changed]))
        k += 1
    return boots, conflict
