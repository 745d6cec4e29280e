"""The power-up rule under delayed frames (issue #11, rules 3 and 5).

A log starts at the firmware's power-up when its first ODOM_STATUS page of WHEEL_ENCODERS E2E
counts says the firmware had accepted exactly the log's encoder frames. The frames to count are
those on the bus when the page was MADE (before the summary sent in its tick), or those up to
the frame the pose sent before it names (an encoder frame held back past that tick still comes
before its summary): a page held back by ``--faults delay`` reaches the bus after encoder
frames it could not count. Before, the judges counted up to the page's arrival:
a firmware off by 2 LSB from power-up was taken for a cut log, the start fitted to its samples
took the constant offset in, and it PASSed; and a log cut by as many encoder frames as the page
was late was taken for a power-up, so a right firmware FAILed from (0, 0, 0).

Here, whole (``analyze``), streamed (the CLI's ``analyze``) and live (the monitor model) agree:
on short drives with delays drawn, a firmware whose X or Y is 2 LSB off from power-up FAILs
(where it lost no encoder frame before its first count page: see the test) and a right one
PASSes; the drives found before FAIL, 1 LSB off too; a right firmware's log cut after its
power-up PASSes from a fitted start. The scenarios are checked with cantools in the test
(``first_count_page``), not with the judges' code.
"""

from __future__ import annotations

import io
from collections.abc import Iterator
from contextlib import contextmanager, redirect_stdout
from pathlib import Path

import can
import pytest
from hypothesis import HealthCheck, Phase, assume, example, given, settings
from hypothesis import strategies as st

import odocan.firmware.frames as fw_frames
from odocan.firmware.errors import ErrorMask
from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import HEADING_LSB_RAD, POSITION_LSB_M, analyze
from odocan.host.judge.monitor import BusMonitor
from odocan.sim.robot import load
from tests.dbc_typed import load_can_dbc, numbers

KOBUKI = load("kobuki")
DBC = Path(__file__).resolve().parents[1] / "dbc" / "odocan.dbc"
ENCODERS_ID, POSE_X_ID, STATUS_ID = 0x100, 0x200, 0x380
# whole ms, not 1 ms past a 10 ms boundary (test_reorder.DELAYS_MS: the firmware's own edge)
DELAYS_MS = [d for d in range(2, 40) if d % 10 != 1]


@contextmanager
def _off_by(signal: str | None, lsb: int) -> Iterator[None]:
    """The Python firmware with its ODOM_POSE_X ``X`` or ODOM_POSE_Y ``Y`` ``lsb`` off (None:
    right), from power-up on."""
    if signal is None:
        yield
        return
    right_x, right_y = fw_frames.pack_odom_pose_x, fw_frames.pack_odom_pose_y

    def wrong_x(counter: int, enc_counter: int, x_100um: int, heading_bam16: int,
                errors: ErrorMask) -> bytes:
        return right_x(counter, enc_counter, x_100um + lsb, heading_bam16, errors)

    def wrong_y(counter: int, enc_counter: int, y_100um: int, turns: int,
                errors: ErrorMask) -> bytes:
        return right_y(counter, enc_counter, y_100um + lsb, turns, errors)

    with pytest.MonkeyPatch.context() as monkeypatch:
        if signal == "X":
            monkeypatch.setattr(fw_frames, "pack_odom_pose_x", wrong_x)
        else:
            monkeypatch.setattr(fw_frames, "pack_odom_pose_y", wrong_y)
        yield


def _run(path: Path, duration_s: int, seed: int, faults: str,
         wrong: tuple[str | None, int] = (None, 0)) -> int:
    argv = ["run", "--robot", "kobuki", "--duration", str(duration_s), "--seed", str(seed),
            "--faults", faults, "--log", str(path), "--firmware", "python"]  # patched: never C
    with _off_by(*wrong), redirect_stdout(io.StringIO()):
        return main(argv)


def _live_passes(path: Path) -> bool:
    """The monitor model's verdict: its pose vs its reference within one LSB each."""
    monitor = BusMonitor(KOBUKI)
    with can.LogReader(path) as reader:
        for msg in reader:
            monitor.feed(msg, now_s=msg.timestamp)
    ref = monitor.tracker.vs_reference
    return bool(ref.max_dpos_m <= POSITION_LSB_M and ref.max_dheading_rad <= HEADING_LSB_RAD)


def _verdicts(path: Path) -> dict[str, bool]:
    with redirect_stdout(io.StringIO()):
        streamed = main(["analyze", str(path), "--robot", "kobuki"]) == 0
    return {"whole": analyze(read_log(path), KOBUKI).passed, "streamed": streamed,
            "live": _live_passes(path)}


def first_count_page(path: Path) -> tuple[int, int | None, int]:
    """With cantools, the log's first ODOM_STATUS page of WHEEL_ENCODERS counts: its ENC_E2E_OK,
    the encoder frames before the summary sent in its tick (the latest summary before it, its
    COUNTER one less; None when that is not it), the encoder frames before the page itself."""
    db = load_can_dbc(DBC)
    encoders, summary = 0, None
    with can.LogReader(path) as reader:
        for msg in reader:
            if msg.arbitration_id == ENCODERS_ID:
                encoders += 1
            elif msg.arbitration_id == STATUS_ID:
                signals = numbers(db, STATUS_ID, msg.data)
                if signals["PAGE"] == 0:
                    summary = (int(signals["COUNTER"]), encoders)
                elif signals["PAGE"] == 2:
                    made = summary[1] if summary and summary[0] == (
                        int(signals["COUNTER"]) - 1) % 16 else None
                    return int(signals["ENC_E2E_OK"]), made, encoders
    raise AssertionError("no count page")


def named_in_its_tick(path: Path) -> int | None:
    """With cantools, the encoder frames up to the one the latest ODOM_POSE_X before the first
    count page's tick names (before the summary sent in its tick, when that is the latest
    summary before the page; else before the page): the latest of the last 8 encoder frames
    before that pose whose COUNTER is its ENC_COUNTER. None when there is none."""
    db = load_can_dbc(DBC)
    counters: list[int] = []
    named: int | None = None
    summary: tuple[int, int | None] | None = None
    with can.LogReader(path) as reader:
        for msg in reader:
            if msg.arbitration_id == ENCODERS_ID:
                counters.append(int(numbers(db, ENCODERS_ID, msg.data)["COUNTER"]))
            elif msg.arbitration_id == POSE_X_ID:
                enc = int(numbers(db, POSE_X_ID, msg.data)["ENC_COUNTER"])
                hits = [i for i in range(max(0, len(counters) - 8), len(counters))
                        if counters[i] == enc]
                named = hits[-1] + 1 if hits else None
            elif msg.arbitration_id == STATUS_ID:
                signals = numbers(db, STATUS_ID, msg.data)
                if signals["PAGE"] == 0:
                    summary = (int(signals["COUNTER"]), named)
                elif signals["PAGE"] == 2:
                    tick = summary and summary[0] == (int(signals["COUNTER"]) - 1) % 16
                    return summary[1] if summary and tick else named
    raise AssertionError("no count page")


def lost_before_first_count_page(path: Path) -> int:
    """With cantools, the encoder frames the firmware says it lost or refused out of sequence
    (ENC_E2E_LOST + ENC_E2E_WRONG_SEQ) on its first page of WHEEL_ENCODERS counts."""
    db = load_can_dbc(DBC)
    with can.LogReader(path) as reader:
        for msg in reader:
            if msg.arbitration_id == STATUS_ID:
                signals = numbers(db, STATUS_ID, msg.data)
                if signals["PAGE"] == 2:
                    return int(signals["ENC_E2E_LOST"] + signals["ENC_E2E_WRONG_SEQ"])
    raise AssertionError("no count page")


@settings(max_examples=10, deadline=None, suppress_health_check=[
    HealthCheck.too_slow, HealthCheck.function_scoped_fixture, HealthCheck.filter_too_much])
@given(seed=st.integers(0, 1000), delay_ms=st.sampled_from(DELAYS_MS),
       share=st.sampled_from([0.05, 0.1, 0.2]), wrong=st.sampled_from([None, "X", "Y"]))
def test_two_lsb_off_from_power_up_fails_under_delay(
    tmp_path: Path, seed: int, delay_ms: int, share: float, wrong: str | None
) -> None:
    """2 s drives, delays drawn: the right firmware PASSes whole, streamed, live and ``run``;
    X or Y 2 LSB off FAILs them all where (cantools) the firmware lost no encoder frame before
    its first count page and the frames before that page, before its tick's summary or up to
    the frame the pose before that names are the ones it counted. Left open, 1-2 % of the
    drives: where it lost one, a placement at that gap before the first sample judged may
    absorb up to its allowance, 2 LSB too (seed 720, delay=0.1:20, X)."""
    path = tmp_path / "drive.blf"
    code = _run(path, 2, seed, f"delay={share}:{delay_ms},seed={seed}", (wrong, 2))
    if wrong is not None:
        ok, before_summary, before_page = first_count_page(path)
        counted = (before_summary, before_page, named_in_its_tick(path))
        assume(lost_before_first_count_page(path) == 0 and ok in counted)
    verdicts = {"run": code == 0, **_verdicts(path)}
    assert verdicts == dict.fromkeys(verdicts, wrong is None), verdicts


# (seed, delay ms, share, signal, LSB off) on 2 s drives: each PASSed before in one judge or more
FOUND = [(310, 22, 0.2, "Y", 2), (48, 10, 0.05, "X", 2), (760, 25, 0.2, "Y", 1),
         (686, 5, 0.1, "X", 1), (702, 16, 0.1, "X", 1), (511, 2, 0.1, "X", 2),
         (934, 13, 0.2, "X", 2)]


@pytest.mark.parametrize("case", FOUND, ids=[f"{c[3]}{c[4]}-{c[0]}" for c in FOUND])
def test_off_from_power_up_fails_in_these(
    tmp_path: Path, case: tuple[int, int, float, str, int]
) -> None:
    """Before (main at f082d3d): 310 and 760 PASSed everywhere (the first count page late), 48
    too (test_reorder's drive, 2 s here), 686 PASSed live (the power-up proven before the
    integrator was known: the held samples judged from the fitted start); 702 (PASSed live on
    powerup2's base) was already FAILed by main's hold. 511 and 934 PASSed everywhere before
    the pose rule (``powerup.pose_named``): an encoder frame held back past the page's tick
    (511: 2 ms), or both status frames of that tick late past one (934), came before the
    summary on the bus, so the frames before it were one more than the firmware had counted;
    the pose sent in that tick names the last frame it counted. 1 LSB is not drawn: a sample
    whose rounding is 0 is exactly within the tolerance."""
    seed, delay_ms, share, signal, lsb = case
    path = tmp_path / "drive.blf"
    code = _run(path, 2, seed, f"delay={share}:{delay_ms},seed={seed}", (signal, lsb))
    verdicts = {"run": code == 0, **_verdicts(path)}
    assert not any(verdicts.values()), verdicts


def test_a_cut_log_is_never_taken_for_a_power_up(tmp_path: Path) -> None:
    """A right firmware, ``delay=0.1:55,seed=5``: its first count page, made with 11 encoder
    frames on the bus, came after the 15th. The log cut before the 5th (4 frames the firmware
    counted are not in it; the page's summary still says UPTIME 0): counting up to the page
    would find the firmware's 11, take the log for a power-up and judge from (0, 0, 0) on a
    frame the robot had moved by (1.1 mm: FAIL). Counting up to the page's summary finds 7:
    the start is fitted, and the right firmware PASSes everywhere."""
    whole_log, cut = tmp_path / "whole.blf", tmp_path / "cut.blf"
    assert _run(whole_log, 2, 5, "delay=0.1:55,seed=5") == 0
    assert first_count_page(whole_log) == (11, 11, 15)
    with can.LogReader(whole_log) as reader, can.BLFWriter(cut) as writer:
        for msg in reader:
            if msg.timestamp >= 0.035:  # the encoder frames at 0, 10, 20 and 30 ms cut
                writer.on_message_received(msg)
    assert first_count_page(cut) == (11, 7, 11)
    assert _verdicts(cut) == {"whole": True, "streamed": True, "live": True}
    assert analyze(read_log(cut), KOBUKI).report["reference_start"] == "fitted"


@settings(max_examples=6, deadline=None, phases=[Phase.explicit, Phase.generate],
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 1000), delay_ms=st.sampled_from([d for d in DELAYS_MS if d < 20]),
       share=st.sampled_from([0.1, 0.2]), cut=st.integers(1, 6))
@example(seed=128, delay_ms=10, share=0.2, cut=1)
def test_a_cut_log_under_delay_passes_a_right_firmware(
    tmp_path: Path, seed: int, delay_ms: int, share: float, cut: int
) -> None:
    """A right firmware's 2 s drive, delays drawn, its log cut before its ``cut``-th encoder
    frame on the bus (the firmware counted frames the log lacks; the summary of the first count
    page's tick still says UPTIME 0): the judge must fit its start, else the log is judged from
    (0, 0, 0) on a frame the robot had moved by and FAILs. (The counts of every frame on the bus
    are no proxy for that: seed 128, ``delay=0.2:10``, cut 1: the firmware refused a held frame,
    so its 10 equal the cut log's 10 frames, but the judge counts what it accepted, as the
    firmware does, and fits.) It PASSes whole, streamed and live. Delays under two periods: a
    cut log with frames held longer can FAIL a right firmware from its fitted start, whatever
    the power-up rule says (seed 313, delay=0.2:36, cut 6: heading 0.16 rad off on main too;
    left open). Not shrunk (each example is a drive)."""
    whole_log, cut_log = tmp_path / "whole.blf", tmp_path / "cut.blf"
    assert _run(whole_log, 2, seed, f"delay={share}:{delay_ms},seed={seed}") == 0
    with can.LogReader(whole_log) as reader, can.BLFWriter(cut_log) as writer:
        for msg in reader:
            cut -= msg.arbitration_id == ENCODERS_ID
            if cut < 0:
                writer.on_message_received(msg)
    assert analyze(read_log(cut_log), KOBUKI).report["reference_start"] == "fitted"
    assert _verdicts(cut_log) == {"whole": True, "streamed": True, "live": True}


def heard_by_its_tick(path: Path) -> tuple[int, int]:
    """With cantools: the encoder frames the firmware had received when it made its first count
    page, by its own counts (ENC_E2E_OK + REPEATED + CRC_ERROR + WRONG_SEQ), and the encoder
    frames on the bus before that page's tick bound: the least, over the summaries before it, of
    the summary's time plus 100 ms (the DBC's ODOM_STATUS cycle) per cycle its COUNTER is behind
    the page's summary (two frames a cycle)."""
    db = load_can_dbc(DBC)
    stamps: list[float] = []
    summaries: list[tuple[int, float]] = []
    with can.LogReader(path) as reader:
        for msg in reader:
            if msg.arbitration_id == ENCODERS_ID:
                stamps.append(msg.timestamp)
            elif msg.arbitration_id == STATUS_ID:
                signals = numbers(db, STATUS_ID, msg.data)
                if signals["PAGE"] == 0:
                    summaries.append((int(signals["COUNTER"]), msg.timestamp))
                elif signals["PAGE"] == 2:
                    behind = [(int(signals["COUNTER"]) - 1 - c) % 16 for c, _ in summaries]
                    bound = min(t + 0.1 * (b // 2) for (_, t), b in zip(summaries, behind,
                                                                      strict=True) if b % 2 == 0)
                    received = sum(int(signals[f"ENC_E2E_{k}"])
                                   for k in ("OK", "REPEATED", "CRC_ERROR", "WRONG_SEQ"))
                    return received, sum(t < bound for t in stamps)
    raise AssertionError("no count page")


def test_a_page_whose_whole_tick_came_late_counts_the_frames_before_its_tick(
    tmp_path: Path,
) -> None:
    """Kobuki, 4 s, ``delay=0.2:24,seed=670`` (the lockout work's find; test_reorder's helpers):
    the first encoder frame (COUNTER 0) came 24 ms late, after COUNTER 1, so the firmware primed
    on COUNTER 1; the summary and the count page of the 100 ms tick came 24 ms late, after two
    encoder frames the firmware could not count, and so did the poses of the 120 ms tick. So
    the frames before the page's summary (13) and up to the frame the latest pose before it
    names (13) are not the firmware's ENC_E2E_OK (8, of 11 frames received: 3 out of
    sequence), and the log was not proven to start at power-up: its start fitted to the
    samples took a firmware's constant 2 LSB in X, which PASSed whole, streamed, live and
    ``run``. The summary of the tick before (the firmware's first, at 1 ms) bounds the page's
    tick to 101 ms: the 11 frames before it are the ones the firmware had received (cantools,
    ``heard_by_its_tick``), the judge counts 8 of them accepted, and the 2 LSB FAIL all four;
    the right firmware PASSes all four from (0, 0, 0)."""
    wrong, right = tmp_path / "wrong.blf", tmp_path / "right.blf"
    code = _run(wrong, 4, 670, "delay=0.2:24,seed=670", ("X", 2))
    assert first_count_page(wrong) == (8, 13, 13)
    assert named_in_its_tick(wrong) == 13
    assert heard_by_its_tick(wrong) == (11, 11)
    verdicts = {"run": code == 0, **_verdicts(wrong)}
    assert not any(verdicts.values()), verdicts
    code = _run(right, 4, 670, "delay=0.2:24,seed=670")
    assert {"run": code == 0, **_verdicts(right)} == dict.fromkeys(verdicts, True)
    assert analyze(read_log(right), KOBUKI).report["reference_start"] == "power-up"


@settings(max_examples=8, deadline=None, suppress_health_check=[
    HealthCheck.too_slow, HealthCheck.function_scoped_fixture, HealthCheck.filter_too_much])
@given(seed=st.integers(0, 1000), delay_ms=st.sampled_from([d for d in DELAYS_MS if d >= 20]),
       share=st.sampled_from([0.1, 0.2]), wrong=st.sampled_from([None, "X"]))
@example(seed=139, delay_ms=22, share=0.1, wrong="X")  # the first summary held back past the
@example(seed=99, delay_ms=39, share=0.1, wrong="X")  # page: live fitted its start (see below)
def test_two_lsb_off_fails_under_delays_of_two_periods_and_more(
    tmp_path: Path, seed: int, delay_ms: int, share: float, wrong: str | None
) -> None:
    """2 s drives, delays of 20-39 ms drawn: the right firmware PASSes whole, streamed, live
    and ``run``; X 2 LSB off FAILs them all where (cantools) the frames before the first count
    page's tick bound are those the firmware had received, or its ENC_E2E_OK is one of the
    counts ``test_two_lsb_off_from_power_up_fails_under_delay`` checks. Seed 139
    ``delay=0.1:22`` (99 ``0.1:39`` alike): the summary of the first tick (UPTIME 0) came after
    the first count page, held back; live read no first UPTIME at the page, fitted the start
    within the rounding (the 0.2 mm taken as its anchor: 0.06 mm) and PASSed the 2 LSB."""
    path = tmp_path / "drive.blf"
    code = _run(path, 2, seed, f"delay={share}:{delay_ms},seed={seed}", (wrong, 2))
    if wrong is not None:
        ok, before_summary, before_page = first_count_page(path)
        received, before_tick = heard_by_its_tick(path)
        assume(received == before_tick
               or ok in (before_summary, before_page, named_in_its_tick(path)))
    verdicts = {"run": code == 0, **_verdicts(path)}
    assert verdicts == dict.fromkeys(verdicts, wrong is None), verdicts


@pytest.mark.parametrize("cut", range(1, 7))
def test_cuts_of_the_late_tick_drive_are_fitted(tmp_path: Path, cut: int) -> None:
    """The right firmware's ``delay=0.2:24,seed=670`` drive (4 s), its log cut before its
    ``cut``-th encoder frame on the bus: the judge fits its start and it PASSes whole, streamed
    and live. Before, cut 3 was taken for a power-up (main too): the firmware counted 2 frames
    the log lacks (of 3: one it refused), and the count page's tick came late past 2 more, so
    the 8 accepted of the 10 before its summary (cantools: ``first_count_page``) matched, and
    the right firmware FAILed from (0, 0, 0). The log's first status frame is then not of the
    firmware's first cycle (COUNTER 2: ``powerup.holds_first_cycle``)."""
    whole_log, cut_log = tmp_path / "whole.blf", tmp_path / "cut.blf"
    assert _run(whole_log, 4, 670, "delay=0.2:24,seed=670") == 0
    left = cut
    with can.LogReader(whole_log) as reader, can.BLFWriter(cut_log) as writer:
        for msg in reader:
            left -= msg.arbitration_id == ENCODERS_ID
            if left < 0:
                writer.on_message_received(msg)
    if cut == 3:
        assert first_count_page(cut_log) == (8, 10, 10)
    assert analyze(read_log(cut_log), KOBUKI).report["reference_start"] == "fitted"
    assert _verdicts(cut_log) == {"whole": True, "streamed": True, "live": True}
