"""A frame heard between a rebooted firmware's mailbox read and its count page: every judge
counts the page back from the frame the page's tick's pose names (``host.judge.pagetick``;
issue #11, rule 5), unless the page was held back.

Found by ``tests/test_trial38.py`` on a loaded machine: the restarted firmware made its first
count page (OK 9) in a tick whose pose named the frame of 3.8283 s, while the frame of 3.8323 s
reached the monitor 0.4 ms before that pose; counted from it, the new life started a frame late
and the correct firmware was POSE WRONG (1.8 mm, 6.3 mrad). Made deterministic here from a
lockstep drive (pmir, random seed 5, ``reboot=5:0.1``): its recorder lost the power-up pose (so
the page alone tells the frame primed on, as ``tests/test_reboot_first_page_losses.py`` does)
and the first encoder frame after the page's tick is moved to 0.1 ms before that tick's pose
(``moved``). Before: the monitor and the bridge POSE WRONG, 5.7 mm and 18.8 mrad; ``analyze``
whole and streamed FAIL. Two edits the rule must not be fooled by: the page and its summary held
back 50 ms to right after a later tick's pose (``held``: counted from that pose, the life
started 5 frames late and every judge FAILed or said POSE WRONG), and an older pose held back to
right before the page (``behind``; here the boot summary bounds the start anyway, so
``test_only_the_page_ticks_pose_names_its_frame`` proves the rule itself).
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from odocan.firmware import frames as fr
from odocan.host.cli.app import main
from odocan.host.judge.pagetick import TICK_GAP_S, named_after
from odocan.sim.contract import DBC_PATH
from tests.dbc_typed import integers, load_can_dbc
from tests.independent_checker import HEADING_LSB_RAD, POSITION_LSB_M
from tests.judges_cli import STREAMS, analyze, live_judges, raise_x_10_mm

ROBOT, REBOOT_S = "pmir", 5.0
HELD_S = 0.05  # how long ``_held`` holds the first count page back
ENC_ID, POSE_X_ID, POSE_Y_ID = fr.WHEEL_ENCODERS_ID, fr.ODOM_POSE_X_ID, fr.ODOM_POSE_Y_ID
STATUS_ID = fr.ODOM_STATUS_ID


Row = tuple[float, int, bytes]  # bus time (s), CAN ID, data


def _row(line: str) -> Row:
    stamp, _, frame = line.split()[:3]
    can_id, data = frame.split("#")
    return float(stamp.strip("()")), int(can_id, 16), bytes.fromhex(data)


def _relocated(lines: list[str], gone: list[int], moves: dict[int, float]) -> list[str]:
    """``lines`` without those at ``gone``, each of ``moves`` re-stamped (bus time s) and put
    after the frames stamped at or before it (the log's stamps rise)."""
    kept = [(_row(line)[0], line) for k, line in enumerate(lines) if k not in (*gone, *moves)]
    assert all(a[0] <= b[0] for a, b in itertools.pairwise(kept))
    for k, t_s in sorted(moves.items(), key=lambda move: move[1]):
        at = next((j for j, (stamp, _) in enumerate(kept) if stamp > t_s), len(kept))
        kept.insert(at, (t_s, _restamped(lines[k], t_s)))
    return [line for _, line in kept]


def _restamped(line: str, t_s: float) -> str:
    return f"({t_s:.6f})" + line[line.index(")") + 1:]


def _first_page(rows: list[Row]) -> tuple[list[int], int, int]:
    """The power-up pose's halves (the first after the reset), the new life's first count page
    and the pose of its tick (log positions)."""
    status = load_can_dbc(DBC_PATH).get_message_by_frame_id(STATUS_ID)
    after = [k for k, row in enumerate(rows) if row[0] >= REBOOT_S]
    power_up = [next(k for k in after if rows[k][1] == i) for i in (POSE_X_ID, POSE_Y_ID)]
    page = next(k for k in after if rows[k][1] == STATUS_ID
                and integers(status, rows[k][2], scaling=False)["PAGE"] == 2)
    pose = max(k for k in range(page) if rows[k][1] == POSE_X_ID)
    assert 0 <= rows[page][0] - rows[pose][0] < 1e-3  # one tick's
    return power_up, page, pose


def _moved(lines: list[str]) -> list[str]:
    """The power-up pose's halves gone, the first encoder frame after the new life's first count
    page moved to 0.1 ms before the pose of the page's tick."""
    rows = [_row(line) for line in lines]
    power_up, page, pose = _first_page(rows)
    late = next(k for k in range(page, len(rows)) if rows[k][1] == ENC_ID)
    return _relocated(lines, power_up, {late: rows[pose][0] - 1e-4})


def _held(lines: list[str]) -> list[str]:
    """The power-up pose's halves gone, the first count page and its summary held back to
    0.1 ms after a pose of HELD_S later (its tick's pose is then a later tick's)."""
    rows = [_row(line) for line in lines]
    power_up, page, _ = _first_page(rows)
    later = next(k for k in range(page, len(rows))
                 if rows[k][1] == POSE_X_ID and rows[k][0] >= rows[page][0] + HELD_S)
    assert rows[page - 1][1] == STATUS_ID  # its summary
    return _relocated(lines, power_up, {page - 1: rows[later][0] + 1e-4,
                                        page: rows[later][0] + 2e-4})


def _behind(lines: list[str]) -> list[str]:
    """The power-up pose's halves gone, the pose of 3 ticks before the first count page's held
    back to between that page's tick's pose and its summary (a later pose than its tick's,
    naming an older frame)."""
    rows = [_row(line) for line in lines]
    power_up, page, pose = _first_page(rows)
    old = [k for k in range(pose) if rows[k][1] == POSE_X_ID][-3]
    assert rows[page - 1][1] == STATUS_ID
    assert rows[page - 1][0] == rows[page][0]
    late = _restamped(lines[old], rows[page][0])
    kept = [(k, line) for k, line in enumerate(lines) if k not in (*power_up, old)]
    summary = next(j for j, (k, _) in enumerate(kept) if k == page - 1)
    return [line for _, line in kept[:summary]] + [late] + [line for _, line in kept[summary:]]


EDITS = {"moved": _moved, "held": _held, "behind": _behind}


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The lockstep drive (``drive``) and its ``EDITS``."""
    work = tmp_path_factory.mktemp("pagetick")
    drive = work / "drive.log"
    assert main(["run", "--robot", ROBOT, "--seed", "5", "--duration", "8", "--faults",
                 f"reboot={REBOOT_S:g}:0.1", "--firmware", "python", "--log", str(drive)]) == 0
    lines = drive.read_text().splitlines(keepends=True)
    out = {"drive": drive}
    for name, edit in EDITS.items():
        out[name] = work / f"{name}.log"
        out[name].write_text("".join(edit(lines)))
    return out


@pytest.mark.parametrize("log", ["drive", *EDITS])
def test_the_live_judges_count_from_the_page_tick(logs: dict[str, Path], log: str) -> None:
    for judge in live_judges(ROBOT, logs[log]):
        tracker = judge.tracker
        assert tracker.reference_starts >= 2
        assert tracker.vs_reference.max_dpos_m <= POSITION_LSB_M, tracker.vs_reference.max_dpos_m
        assert tracker.vs_reference.max_dheading_rad <= HEADING_LSB_RAD


def test_x_10_mm_off_is_still_wrong(logs: dict[str, Path], tmp_path: Path) -> None:
    tampered = tmp_path / "tampered.log"
    assert raise_x_10_mm(logs["moved"], tampered, REBOOT_S + 0.5) > 100
    for judge in live_judges(ROBOT, tampered):
        assert judge.tracker.max_beyond_allowance_m > 9e-3


@pytest.mark.parametrize("log", ["drive", *EDITS])
@pytest.mark.parametrize("stream", STREAMS)
def test_analyze_counts_from_the_page_tick(logs: dict[str, Path], stream: str, log: str) -> None:
    assert analyze(logs[log], stream) == 0


@pytest.mark.parametrize("stream", STREAMS)
def test_analyze_fails_x_10_mm_off(logs: dict[str, Path], stream: str, tmp_path: Path) -> None:
    tampered = tmp_path / "tampered.log"
    assert raise_x_10_mm(logs["moved"], tampered, REBOOT_S + 0.5) > 100
    assert analyze(tampered, stream) == 1


def _named(pose_counters: list[int], page_s: float) -> int | None:
    """``pagetick.named_after`` for a page at log position 100, bus time ``page_s``, after
    poses at positions 90, 95, 99 (bus times 0.96, 0.98, 1.0; their E2E COUNTERs given, the
    last naming ENC_COUNTER 6), the firmware having taken frames 80 .. 98 (COUNTER k mod 16)."""
    poses = (np.array([90, 95, 99]), np.array([0.96, 0.98, 1.0]), np.array(pose_counters),
             np.array([1, 3, 6]))
    taken = np.arange(80, 99)
    return named_after((100, page_s), poses, (taken, taken % 16))


def test_only_the_page_ticks_pose_names_its_frame() -> None:
    assert _named([3, 4, 5], 1.001) == 87  # frame 86 has COUNTER 6: the page counts from it
    assert _named([3, 4, 5], 1.001 + TICK_GAP_S) is None  # heard too long after the pose
    assert _named([3, 5, 1], 1.001) is None  # behind the pose before it: a held-back one
    assert _named([14, 15, 0], 1.001) == 87  # a COUNTER lap
