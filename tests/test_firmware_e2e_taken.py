"""The host's E2E check against the firmware's own, frame by frame, around a bus-off (issue #11: a
FAIL must never blame a correct firmware).

The Python firmware's WHEEL_ENCODERS verdicts are recorded as it makes them (``Reception.usable``
watched: the frames its Profile 2 check took, before the plausibility bound), and compared with
the frames ``check_frames`` accepts in the log, as payloads (a duplicate is one payload taken
once by each). Around each drive's fault they must be the same frames:

* pmir figure8 82, ``delay=0.3:55,busoff=1:1``: the firmware took COUNTER 3, then 9 and 15 of the
  recovery (its bound refused their steps), then the late 2; the host read the poses' proof that
  9 was skipped as an E2E refusal and took 4, 5 and 7 (``host.protocol.e2e_implausible``);
* kobuki figure8 446, ``busoff=2:0.3,delay=0.3:55``: the firmware refused the COUNTER 7 of
  2.31 s, two cycles after the 7 of 1.99 s, as a repeat; the host took it as a new cycle
  (``host.protocol.e2e_repeats``);
* kobuki random 3, ``delay=0.5:150``: the firmware's E2E check took the late COUNTER 5 of 4.20 s
  (its bound refused the step) and refused the on-time 5 of 4.21 s as a repeat; the host read the
  poses' proof that the late 5 was skipped as an E2E refusal and took the on-time 5
  (``host.protocol.e2e_evidence._bound_skip``).

And the rules' pieces on hand-made sequences; the halt's restart rule
(``host.judge.stallrestart``) on its own.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from odocan.firmware import frames as ffr
from odocan.firmware.e2e import E2EReceiver
from odocan.firmware.reception import Reception
from odocan.host.io.logs import read_log
from odocan.host.judge.nearthreshold import COUNTER_RESET_BIT, Resets
from odocan.host.judge.stallrestart import proven, stall_windows, told_otherwise
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import check_frames
from odocan.host.protocol.e2e_evidence import (
    S_LOST,
    S_OK,
    S_REPEATED,
    S_WRONG,
    Evidence,
    settle,
)
from odocan.host.protocol.e2e_implausible import Readings, by_stamps
from odocan.host.protocol.e2e_pages import OkPages
from odocan.host.protocol.e2e_repeats import new_cycles_taken, repeats_by_pages
from tests.judges_cli import watched_run

# name: (robot, scenario, seed, duration s, faults), the window judged (s from the first frame)
DRIVES = {
    "late_frame_a_lap_on": (("pmir", "figure8", 82, 10, "delay=0.3:55,busoff=1:1"), (0.9, 3.0)),
    "busoff_two_cycles": (("kobuki", "figure8", 446, 8, "busoff=2:0.3,delay=0.3:55"), (1.9, 3.0)),
    # the late COUNTER 5 of 4.20 s and 15 of 5.75 s, proven skipped, taken by the firmware's
    # E2E check and refused by its bound (``e2e_evidence._bound_skip``)
    "late_skips_the_bound_s": (("kobuki", "random", 3, 10, "delay=0.5:150"), (3.9, 6.2)),
}
Taken = tuple[Path, list[bytes]]  # the log, the encoder payloads the firmware's E2E took


@pytest.fixture(scope="module", params=sorted(DRIVES))
def taken(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory,
          ) -> Taken:
    (robot, scenario, seed, duration, faults), _ = DRIVES[request.param]
    log = tmp_path_factory.mktemp(request.param) / "d.log"
    payloads: list[bytes] = []
    original: Callable[[Reception, E2EReceiver, bytes], bool] = Reception.usable

    def usable(self: Reception, receiver: E2EReceiver, data: bytes) -> bool:
        ok = original(self, receiver, data)
        if ok and receiver.data_ids is ffr.WHEEL_ENCODERS_DATA_IDS:
            payloads.append(bytes(data))
        return ok

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(Reception, "usable", usable)
        watch, code = watched_run(log, robot, scenario, seed, duration, faults)
    assert code == 0
    assert watch.within_a_thousandth_lsb(), (watch.worst_m, watch.worst_rad)
    return log, payloads


def test_the_host_takes_the_encoder_frames_the_firmware_took(
        taken: Taken, request: pytest.FixtureRequest) -> None:
    log, payloads = taken
    lo_s, hi_s = DRIVES[request.node.callspec.params["taken"]][1]
    frames = read_log(log)
    db = default_plan()
    _, accepted = check_frames(frames, db)
    encoders = BulkDecoder(db).select(frames, "WHEEL_ENCODERS")
    t_s = frames.timestamp_s[encoders] - frames.timestamp_s[0]
    window = encoders[(t_s >= lo_s) & (t_s <= hi_s)]
    heard = {bytes(frames.data[i][:8]) for i in window}
    assert len(heard) > 50
    host = Counter(bytes(frames.data[i][:8]) for i in window if accepted[i])
    firmware = Counter(p for p in payloads if p in heard)
    assert host == firmware, (sorted(round(float(t), 3) for t, i in zip(
        t_s, encoders, strict=True) if (host - firmware)[bytes(frames.data[i][:8])]),
        len(firmware - host))


def _readings(counters: list[int], periods: list[int]) -> Readings:
    return Readings([True] * len(counters), counters, [periods] * 3, [-1] * len(counters),
                    [False] * len(counters), 0)


def test_a_skip_the_bound_made_is_taken_where_it_leads_to_the_proven_frame() -> None:
    """The pmir 82 pattern: 3 taken (proven), 9 (6 periods on: the window takes it; the poses
    say skipped), 4 and 5 on time, then 15 and the proven 2: by the stamps alone 9 and 15 are
    taken and 4, 5 refused, and 2 is within 15's window."""
    counters = [3, 9, 4, 5, 15, 2]
    periods = [0, 6, 5, 1, 0, 3]
    retaken = by_stamps(5, [0, 2, 3], frozenset({0, 5}), frozenset({1}),
                        _readings(counters, periods))
    assert retaken is not None
    assert retaken.place == 0
    assert retaken.taken == [1, 4]
    assert retaken.codes == {1: S_LOST, 2: S_WRONG, 3: S_WRONG, 4: S_LOST}
    # without a skip proof among the frames taken so the rule says nothing
    assert by_stamps(5, [0, 2, 3], frozenset({0, 5}), frozenset(),
                     _readings(counters, periods)) is None
    # nor where the proven frame stays out of every window
    assert by_stamps(5, [0, 2, 3], frozenset({0, 5}), frozenset({1}),
                     _readings(counters, [0, 6, 5, 1, 0, 1])) is None


def _settled(periods: tuple[list[int], list[int], list[int]], taken: set[int]) -> list[int]:
    """The kobuki 3 pattern: the on-time 2 (proven taken), the late 3 and 5 (proven skipped),
    the on-time 5, the late 11 (proven taken)."""
    n = len(periods[0])
    status = settle(np.ones(n, dtype=bool), np.array([2, 3, 5, 5, 11], dtype=np.int64),
                    tuple(np.array(p, dtype=np.int64) for p in periods),  # type: ignore[arg-type]
                    Evidence(frozenset(taken), frozenset({1, 2})), 0, np.zeros(n, dtype=bool))
    return [int(code) for code in status]


def test_a_skip_every_window_takes_after_the_firmware_s_last_frame_is_the_bound_s() -> None:
    strict = [0, 0, 2, 1, 7]
    assert _settled((strict, strict, strict), {0, 4}) == [S_OK, S_OK, S_LOST, S_REPEATED,
                                                            S_LOST]
    # readings that differ (a starved recorder's stamps), even where each takes the 5: the
    # stamps are not the bus's, the skip is the check's
    for wide, narrow in (([0, 0, 3, 1, 7], strict), (strict, [0, 0, 1, 1, 7])):
        assert _settled((strict, wide, narrow), {0, 4}) == [S_OK, S_OK, S_WRONG, S_LOST, S_LOST]
    # the frame before the skip not known the firmware's last (nothing proven taken): as before
    assert _settled((strict, strict, strict), {4}) == [S_OK, S_OK, S_WRONG, S_LOST, S_LOST]


def _pages(repeated: list[int], at: list[int]) -> OkPages:
    return OkPages(np.array(at, dtype=np.intp), np.zeros(len(at), dtype=np.int64),
                   np.array(repeated, dtype=np.int64))


def test_a_new_cycle_the_pages_count_as_a_repeat_is_refused() -> None:
    counter = np.array([5, 6, 7, 7, 12, 15], dtype=np.int64)
    status = np.array([S_OK, S_OK, S_OK, S_LOST, S_LOST, S_LOST], dtype=np.int8)
    enc_pos = np.array([10, 20, 30, 40, 50, 60], dtype=np.intp)
    assert new_cycles_taken(status, counter).tolist() == [False, False, False, True, False,
                                                          False]
    out = repeats_by_pages(status, counter, enc_pos, _pages([0, 1], [5, 100]))
    assert out.tolist() == [S_OK, S_OK, S_OK, S_REPEATED, S_LOST, S_LOST]
    # the firmware counted no repeat there (a recorder lost the frames between): kept
    assert repeats_by_pages(status, counter, enc_pos, _pages([0, 0], [5, 100])) is status
    # a repeat the host refused too accounts for the page's: kept
    twice = np.array([S_OK, S_REPEATED, S_OK, S_LOST, S_LOST, S_LOST], dtype=np.int8)
    counted = repeats_by_pages(twice, np.array([5, 5, 7, 7, 12, 15]), enc_pos,
                               _pages([3, 4], [5, 100]))
    assert counted.tolist() == twice.tolist()


def test_a_restart_across_a_halt_follows_the_firmware_s_word_unless_proven() -> None:
    """Frames 0..5 (CTRL_UPTIME 4, 4, 5, 7, 6, 6); the firmware named frame 1 last before its
    halt (break 2) and frame 5 first after it: the step into frame 4 (6 after 7) is no proof (a
    frame of CTRL_UPTIME 4 may have been its last), and its summaries say it did not re-prime."""
    uptime = np.array([4, 4, 5, 7, 6, 6], dtype=np.int64)
    stamps = np.arange(6, dtype=np.float64) * 0.5
    windows = stall_windows(np.array([2]), np.array([0, 1, 5]))
    assert windows == ((2, 5),)
    assert not proven(uptime, 1, 4)
    assert proven(np.array([4, 4, 5, 7, 3, 3]), 1, 4)
    restart = np.array([False, False, False, True, False])
    quiet = Resets(np.array([0.0, 3.0]), np.array([0, 0]), cycle_s=0.01)
    said = Resets(np.array([0.0, 3.0]), np.array([0, COUNTER_RESET_BIT]), cycle_s=0.01)
    assert told_otherwise(restart, uptime, stamps, 0, windows, quiet).tolist() == [False] * 5
    assert told_otherwise(restart, uptime, stamps, 0, windows, said).tolist() == restart.tolist()
    assert told_otherwise(restart, uptime, stamps, 0, (), quiet).tolist() == restart.tolist()
