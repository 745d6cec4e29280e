"""The power-up rule (``host.judge.analysis`` module docstring, step 4): whether a log, or a
firmware life in it, starts at the firmware's power-up, so that its reference starts exactly at
(0, 0, 0) on the encoder frame the firmware primed on, whatever its first pose says (a firmware
that powers up off (0, 0, 0) is wrong, and is judged from (0, 0, 0)). The evidence is the
firmware's own: the first ODOM_STATUS summary (UPTIME 0) and its first ENC_E2E_OK page (it had
accepted exactly the log's encoder frames). A log cut after the power-up lacks the second, so
its start is fitted (``host.judge.reference_path``); a log whose first count pages were lost
after a stall at power-up has the stall's evidence instead (``host.judge.stallpowerup``)."""

from __future__ import annotations

from collections.abc import Collection

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.samples import ENC_E2E_PAGE, Poses
from odocan.host.protocol.decode import BulkDecoder, DecodeError

NAMED_SPAN = 8  # a pose names one of the latest 8 encoder frames (``livepose.recent``)


def starts_at_power_up(
    frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder, onboard: Poses,
    *, by_tick: bool = True
) -> bool:
    """The log starts at the firmware's power-up (module docstring, step 4): the first accepted
    ODOM_STATUS summary says UPTIME 0 and the first ENC_E2E_OK page says the firmware had
    accepted exactly the log's encoder frames (it primed on the log's first), whatever the
    first on-board sample reads: a firmware whose power-up pose is not (0, 0, 0) is judged from
    (0, 0, 0), and the log's first accepted ODOM_STATUS frame is of the firmware's first cycle
    (``holds_first_cycle``). Without that page, ``zero_first_sample`` stands in for it.
    ``by_tick`` False: the page's tick bound (``heard_by_tick``) is no evidence (a firmware that
    halted at power-up sent its page a stall after the bound: ``stallpowerup.log_power_up``)."""
    try:
        page = decoder.decode_page(frames, "ODOM_STATUS", 0)
    except DecodeError:
        return False
    if "UPTIME" not in page:
        return False
    uptime = page["UPTIME"][accepted[page["index"]]]
    if len(uptime) == 0 or int(uptime[0]) != 0:
        return False
    counted = counted_only_the_log(frames, accepted, decoder, by_tick=by_tick)
    if counted is None:
        return zero_first_sample(onboard)
    try:
        status = decoder.decode(frames, "ODOM_STATUS")
    except DecodeError:
        return counted
    first = status["COUNTER"][accepted[status["index"]]][:1] if "COUNTER" in status else None
    return counted and holds_first_cycle(None if first is None else int(first[0]))


def life_powered_up(frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder,
                    onboard: Poses, *, log_start: bool) -> bool:
    """Whether ``frames``, read from the first frame of a firmware life, start at its power-up:
    a reboot's life when the firmware counted only these frames (``saw_only_the_log``); the
    log's first life (``log_start``) by the log's own rule (``starts_at_power_up``: a log cut
    after the power-up must not be judged from (0, 0, 0))."""
    if log_start:
        return starts_at_power_up(frames, accepted, decoder, onboard)
    return saw_only_the_log(frames, accepted, decoder)


def holds_first_cycle(counter: int | None) -> bool:
    """The log's first accepted ODOM_STATUS frame (its ``counter``) is of the firmware's first
    cycle (E2E counters start at 0 at power-up; two frames a cycle: the summary, then one
    page): else the log lacks the firmware's first frames, and a count page whose tick came
    late past as many encoder frames as the log lacks would pass for a power-up (kobuki 4 s,
    ``delay=0.2:24,seed=670`` cut before its 3rd encoder frame). The summary of the first cycle
    may be refused, held back behind its page (``delay=0.1:15,seed=2``). True when the frames
    have no COUNTER."""
    return counter is None or counter < 2


def zero_first_sample(onboard: Poses) -> bool:
    """The first on-board sample names the first accepted encoder frame and reads exactly 0:
    the power-up rule's last evidence when the firmware sends no ENC_E2E_OK page (a recorder
    started in its first second after the robot moved less than half an LSB passes it too, and
    an offset from power-up is then fitted, not failed)."""
    if int(onboard.enc[0]) != 0 or int(onboard.heading_raw[0]) != 0:
        return False
    return bool(onboard.x_m[0] == 0.0 and onboard.y_m[0] == 0.0 and onboard.heading_rad[0] == 0.0)


def saw_only_the_log(
    frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder
) -> bool:
    """``counted_only_the_log``, True when the log has no such page (other firmwares need not
    send it)."""
    return counted_only_the_log(frames, accepted, decoder) is not False


def counted_only_the_log(
    frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder, *,
    by_tick: bool = True
) -> bool | None:
    """Whether the firmware had accepted exactly the log's encoder frames when it made its first
    ODOM_STATUS page of WHEEL_ENCODERS E2E counts (ENC_E2E_OK): then it primed on the log's first
    encoder frame. None when the log has no such page. The frames counted are those before the
    page was made (``made_at``), not before it reached the bus (a page held back comes after
    encoder frames it could not count); or those up to the frame the latest pose before that
    point names (``pose_named``: an encoder frame held back past the tick that made the page
    came before it on the bus all the same). The count is ENC_E2E_OK, or ENC_E2E_OK plus
    ENC_E2E_LOST (u8): a firmware whose mailbox dropped frames the bus carried counted each
    frame since its first once, accepted or lost. A log cut by some frames after the power-up
    (the firmware counted them too) matches neither unless its page's tick came late past as
    many frames, both its summary and the poses before it (a later tick's pose). ``by_tick``
    False: without the tick bound's count (``starts_at_power_up``)."""
    try:
        page = decoder.decode_page(frames, "ODOM_STATUS", ENC_E2E_PAGE)
        summary = decoder.decode_page(frames, "ODOM_STATUS", 0)
    except DecodeError:
        return None
    if "ENC_E2E_OK" not in page or not accepted[page["index"]].any():
        return None
    first, made, counts = _first_count(page, summary, accepted, decoder)
    encoders = decoder.select(frames, "WHEEL_ENCODERS")
    in_log = int(np.count_nonzero(accepted[encoders] & (encoders < made)))
    if in_log & 0xFFFF in counts or pose_named(frames, accepted, decoder, made) in counts:
        return True
    return by_tick and heard_by_tick(frames, accepted, decoder, (first, made)) in counts


def primed_after(frames: FrameArrays, accepted: npt.NDArray[np.bool_],
                 decoder: BulkDecoder) -> int | None:
    """The log's encoder frame the firmware primed on, when its first count page says it had
    not accepted the log's first ``k`` (1 or more) and so primed on frame ``k`` (issue #11:
    its FIFO drained at tick 0, it primed on frame 1, and a log that holds one frame more than
    it counted had its start fitted, absorbing a firmware 1 m off). The frames it did not
    accept before priming are on the bus before its first cycle: the log's first ODOM_STATUS
    frame is of that cycle (``holds_first_cycle``, the first summary UPTIME 0) and holds ``k``
    accepted encoder frames or more before it. The count is the frames before the page was
    made (``made_at``) less ENC_E2E_OK (or ENC_E2E_OK + ENC_E2E_LOST), and the page's tick
    bound (``heard_by_tick``), when it has one, must count the same: a page held back on the
    bus past later frames overcounts, and is no proof. A recorder started late is not taken:
    the firmware counted the frames it lacks (fewer in the log than counted). None when not
    proven (``counted_only_the_log`` True is frame 0: not this rule's). A recorder stamping
    ODOM_STATUS late (a gateway's 10-50 ms) shifts the count page and its tick bound alike past
    frames the firmware had counted, so ``k`` is only ever too large: the firmware primed on
    frame ``k`` or before (``host.judge.primedrange``)."""
    try:
        status = decoder.decode(frames, "ODOM_STATUS")
        summary = decoder.decode_page(frames, "ODOM_STATUS", 0)
        page = decoder.decode_page(frames, "ODOM_STATUS", ENC_E2E_PAGE)
    except DecodeError:
        return None
    if not {"COUNTER"} <= status.keys() or "UPTIME" not in summary \
            or "ENC_E2E_OK" not in page or not accepted[page["index"]].any():
        return None
    heard_status = status["index"][accepted[status["index"]]]
    uptime = summary["UPTIME"][accepted[summary["index"]]]
    if not len(uptime) or int(uptime[0]) != 0 or not holds_first_cycle(
            int(status["COUNTER"][accepted[status["index"]]][0])):
        return None
    first, made, counts = _first_count(page, summary, accepted, decoder)
    encoders = decoder.select(frames, "WHEEL_ENCODERS")
    in_log = int(np.count_nonzero(accepted[encoders] & (encoders < made)))
    before_first = int(np.count_nonzero(accepted[encoders] & (encoders < int(heard_status[0]))))
    by_tick = heard_by_tick(frames, accepted, decoder, (first, made))
    return primed_by_count(in_log, counts, by_tick, before_first)


def first_pose_named(frames: FrameArrays, accepted: npt.NDArray[np.bool_],
                     decoder: BulkDecoder) -> int | None:
    """The log's encoder frame (0-based, accepted ones) the firmware's first pose names: it
    primed on that frame or before (a pose names the frame it integrated last, never one
    before its priming frame), whatever a recorder stamping ODOM_STATUS late made its count
    page say (its poses are not delayed: ``host.judge.primedrange``). None when not told."""
    poses = decoder.select(frames, "ODOM_POSE_X")
    heard = poses[accepted[poses]]
    named = None if not len(heard) else pose_named(frames, accepted, decoder, int(heard[0]) + 1)
    return None if named is None else named - 1


def _first_count(page: dict[str, np.ndarray], summary: dict[str, np.ndarray],
                 accepted: npt.NDArray[np.bool_], decoder: BulkDecoder
                 ) -> tuple[int, int, set[int]]:
    """The first accepted count page's frame index, the frame it was made at (``made_at``, by
    the summaries heard before it) and its counts: ENC_E2E_OK, and ENC_E2E_OK + ENC_E2E_LOST
    (u8; the frames it lost after the bus carried them)."""
    keep = accepted[page["index"]]
    first, ok = int(page["index"][keep][0]), int(page["ENC_E2E_OK"][keep][0])
    lost = int(page["ENC_E2E_LOST"][keep][0]) if "ENC_E2E_LOST" in page else 0
    heard = accepted[summary["index"]] & (summary["index"] < first)
    last = (int(summary["index"][heard][-1]), int(summary["COUNTER"][heard][-1])) \
        if heard.any() and "COUNTER" in summary else None
    made = made_at(first, int(page["COUNTER"][keep][0]) if "COUNTER" in page else None, last,
                   status_counter_modulo(decoder))
    return first, made, {ok, (ok + lost) & 0xFFFF}


def primed_by_count(in_log: int, counts: Collection[int], by_tick: int | None,
                    before_first: int) -> int | None:
    """``primed_after``'s rule on its counts: the one ``k`` (1 .. ``before_first``) that the
    log's frames before the page (``in_log``) hold beyond a count the firmware made
    (``counts``), the tick bound's count (``by_tick``) agreeing when there is one."""
    found = {in_log - count for count in counts if 1 <= in_log - count <= before_first}
    if len(found) != 1:
        return None
    k = found.pop()
    return k if by_tick is None or by_tick - k in counts else None


def heard_by_tick(frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder,
                  page: tuple[int, int]) -> int | None:
    """The accepted encoder frames before the first count page was made (``page``: its position
    and ``made_at``'s) that reached the bus before the page's tick bound (``tick_bound_s`` of the
    accepted summaries before it): the count when the page's tick frames were held back past
    encoder frames it could not count, its poses too. None without the evidence."""
    try:
        summary = decoder.decode_page(frames, "ODOM_STATUS", 0)
        counts = decoder.decode_page(frames, "ODOM_STATUS", ENC_E2E_PAGE)
        cycle_ms = decoder.message("ODOM_STATUS").cycle_time
    except DecodeError:
        return None
    keep = accepted[summary["index"]] & (summary["index"] < page[0])
    if "COUNTER" not in summary or "COUNTER" not in counts or not cycle_ms:
        return None
    page_counter = int(counts["COUNTER"][counts["index"] == page[0]][0])
    heard = list(zip(summary["COUNTER"][keep].tolist(),
                     frames.timestamp_s[summary["index"][keep]].tolist(), strict=True))
    bound_s = tick_bound_s(page_counter, heard, status_counter_modulo(decoder), cycle_ms)
    if bound_s is None:
        return None
    encoders = decoder.select(frames, "WHEEL_ENCODERS")
    before = accepted[encoders] & (encoders < page[1]) & (frames.timestamp_s[encoders] < bound_s)
    return int(np.count_nonzero(before))


def tick_bound_s(page_counter: int, summaries: list[tuple[int, float]], modulo: int,
                 cycle_ms: int) -> float | None:
    """A bus time after the tick that made the first count page (COUNTER ``page_counter``) and
    before any frame sent past it: the least over the summaries heard before it (COUNTER, bus
    time) of its time plus as many ODOM_STATUS cycles (``cycle_ms``, two frames each: the
    summary, then one page) as its COUNTER is behind the page's summary. A summary reaches the
    bus after its tick, so each bound is after the page's tick (a COUNTER wrapped past the
    modulo only makes it earlier: fewer frames counted, never a cut log taken for a power-up);
    it is later than that tick by as long as that summary was held back. None when none."""
    bounds = [time_s + ticks * cycle_ms * 0.001 for counter, time_s in summaries
              if (ticks := status_ticks_behind(page_counter, counter, modulo)) is not None]
    return min(bounds) if bounds else None


def status_ticks_behind(page_counter: int, summary_counter: int, modulo: int) -> int | None:
    """How many ODOM_STATUS cycles a summary of COUNTER ``summary_counter`` is before the tick
    of the count page of COUNTER ``page_counter`` (modulo the COUNTER's wrap); None when its
    COUNTER is not a summary's in that send order (two frames a cycle)."""
    behind = (page_counter - 1 - summary_counter) % modulo
    return None if behind % 2 else behind // 2


def pose_named(frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder,
               before: int) -> int | None:
    """``named_count`` of the latest accepted ODOM_POSE_X before position ``before`` (where the
    first count page was made, ``made_at``): the frames the firmware had counted in the tick
    that sent that pose, whatever came late around it. None when there is none."""
    try:
        poses = decoder.decode(frames, "ODOM_POSE_X")
        encoders = decoder.decode(frames, "WHEEL_ENCODERS")
    except DecodeError:
        return None
    keep = accepted[poses["index"]] & (poses["index"] < before)
    if "ENC_COUNTER" not in poses or "COUNTER" not in encoders or not keep.any():
        return None
    heard = accepted[encoders["index"]] & (encoders["index"] < int(poses["index"][keep][-1]))
    return named_count(encoders["COUNTER"][heard], int(np.count_nonzero(heard)),
                       int(poses["ENC_COUNTER"][keep][-1]))


def named_count(counters: npt.NDArray[np.int64], heard: int, named: int) -> int | None:
    """The accepted encoder frames up to and including the one a pose names: its ENC_COUNTER
    (``named``) is the COUNTER of the latest of the last ``NAMED_SPAN`` accepted before it
    (``counters``: theirs, or more; ``heard``: how many in all) with that COUNTER (a pose is
    made after the frame it names). None when none has it. Never more of the log's frames
    than the firmware had counted in the tick of the first count page, unless the pose is
    stale by ``NAMED_SPAN`` frames or came from a later tick (``counted_only_the_log``)."""
    tail = counters[-NAMED_SPAN:]
    hits = np.flatnonzero(tail == named)
    return None if len(hits) == 0 else heard - len(tail) + int(hits[-1]) + 1


def made_at(page_at: int, page_counter: int | None, summary: tuple[int, int] | None,
            modulo: int) -> int:
    """Where in the log the first count page was made: the firmware sends it in the tick of the
    summary page just before it in its ODOM_STATUS send order (COUNTER one less), so when the
    latest summary heard before the page (``summary``: its position and COUNTER) is that one,
    its position (the page may have been held back on the bus after it), else the page's own
    (``page_at``). Both are on the bus no earlier than the tick that made the page, so the
    frames before either are never fewer than the firmware had counted: a log cut after the
    power-up (the firmware counted frames the log lacks) is not taken for a power-up unless
    both frames of that tick came late, each past as many encoder frames as were cut."""
    if summary is None or not same_tick(page_counter, summary[1], modulo):
        return page_at
    return summary[0]


def same_tick(page_counter: int | None, summary_counter: int, modulo: int) -> bool:
    """The summary was sent in the tick of the count page (``made_at``): COUNTER one less."""
    return page_counter is not None and summary_counter == (page_counter - 1) % modulo


def status_counter_modulo(decoder: BulkDecoder) -> int:
    """2 ** the bit length of ODOM_STATUS ``COUNTER`` in the DBC (16 when it has none)."""
    try:
        return 1 << int(decoder.message("ODOM_STATUS").get_signal_by_name("COUNTER").length)
    except (DecodeError, KeyError):
        return 16
