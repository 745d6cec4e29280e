"""A frame heard between a rebooted firmware's mailbox read and its count page: the live judges
count the page back from the frame the page's tick's pose names (``host.judge.pagetick``;
issue #11, rule 5).

Found by ``tests/test_trial38.py`` on a loaded machine: the restarted firmware made its first
count page (OK 9) in a tick whose pose named the frame of 3.8283 s, while the frame of 3.8323 s
reached the monitor 0.4 ms before that pose; counted from it, the new life started a frame late
and the correct firmware was POSE WRONG (1.8 mm, 6.3 mrad). Made deterministic here from a
lockstep drive (pmir, random seed 5, ``reboot=5:0.1``): its recorder lost the power-up pose (so
the page alone tells the frame primed on, as ``tests/test_reboot_first_page_losses.py`` does)
and the first encoder frame after the page's tick is moved to 0.1 ms before that tick's pose.
Before: the monitor and the bridge POSE WRONG, 5.7 mm and 18.8 mrad.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from odocan.firmware import frames as fr
from odocan.host.cli.app import main
from odocan.sim.contract import DBC_PATH
from tests.dbc_typed import integers, load_can_dbc
from tests.independent_checker import HEADING_LSB_RAD, POSITION_LSB_M
from tests.judges_cli import STREAMS, analyze, live_judges, raise_x_10_mm

ROBOT, REBOOT_S = "pmir", 5.0
ENC_ID, POSE_X_ID, POSE_Y_ID = fr.WHEEL_ENCODERS_ID, fr.ODOM_POSE_X_ID, fr.ODOM_POSE_Y_ID
STATUS_ID = fr.ODOM_STATUS_ID


def _moved(lines: list[str]) -> list[str]:
    """The drive's lines: the power-up pose's halves (the first after the reset) gone, the first
    encoder frame after the new life's first count page moved to 0.1 ms before the pose of the
    page's tick."""
    db = load_can_dbc(DBC_PATH)
    status = db.get_message_by_frame_id(STATUS_ID)

    def at(line: str) -> tuple[float, int, bytes]:
        stamp, _, frame = line.split()[:3]
        can_id, data = frame.split("#")
        return float(stamp.strip("()")), int(can_id, 16), bytes.fromhex(data)

    rows = [at(line) for line in lines]
    after = [k for k, row in enumerate(rows) if row[0] >= REBOOT_S]
    power_up = [next(k for k in after if rows[k][1] == i) for i in (POSE_X_ID, POSE_Y_ID)]
    page = next(k for k in after if rows[k][1] == STATUS_ID
                and integers(status, rows[k][2], scaling=False)["PAGE"] == 2)
    pose = max(k for k in range(page) if rows[k][1] == POSE_X_ID)
    late = next(k for k in range(page, len(rows)) if rows[k][1] == ENC_ID)
    stamp = f"({rows[pose][0] - 1e-4:.6f})"
    moved = stamp + lines[late][lines[late].index(")") + 1:]
    kept = [line for k, line in enumerate(lines) if k not in (*power_up, late)]
    out = [*kept[:pose - 2], moved, *kept[pose - 2:]]  # the power-up halves were before it
    assert out[pose - 2 : pose] == [moved, lines[pose]]
    assert rows[pose][0] < rows[page][0] + 1e-3 < rows[late][0]  # one tick's, then the frame
    return out


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The lockstep drive and its edited copy (``_moved``)."""
    work = tmp_path_factory.mktemp("pagetick")
    drive, edited = work / "drive.log", work / "edited.log"
    assert main(["run", "--robot", ROBOT, "--seed", "5", "--duration", "8", "--faults",
                 f"reboot={REBOOT_S:g}:0.1", "--firmware", "python", "--log", str(drive)]) == 0
    lines = drive.read_text().splitlines(keepends=True)
    edited.write_text("".join(_moved(lines)))
    return drive, edited


@pytest.mark.parametrize("edited", [False, True])
def test_the_live_judges_count_from_the_page_tick(logs: tuple[Path, Path], edited: bool) -> None:
    for judge in live_judges(ROBOT, logs[edited]):
        tracker = judge.tracker
        assert tracker.reference_starts >= 2
        assert tracker.vs_reference.max_dpos_m <= POSITION_LSB_M, tracker.vs_reference.max_dpos_m
        assert tracker.vs_reference.max_dheading_rad <= HEADING_LSB_RAD


def test_x_10_mm_off_is_still_wrong(logs: tuple[Path, Path], tmp_path: Path) -> None:
    tampered = tmp_path / "tampered.log"
    assert raise_x_10_mm(logs[1], tampered, REBOOT_S + 0.5) > 100
    for judge in live_judges(ROBOT, tampered):
        assert judge.tracker.max_beyond_allowance_m > 9e-3


@pytest.mark.parametrize("edited", [False, True])
@pytest.mark.parametrize("stream", STREAMS)
def test_analyze_counts_from_the_page_tick(logs: tuple[Path, Path], stream: str,
                                           edited: bool) -> None:
    assert analyze(logs[edited], stream) == 0


@pytest.mark.parametrize("stream", STREAMS)
def test_analyze_fails_x_10_mm_off(logs: tuple[Path, Path], stream: str,
                                   tmp_path: Path) -> None:
    tampered = tmp_path / "tampered.log"
    assert raise_x_10_mm(logs[1], tampered, REBOOT_S + 0.5) > 100
    assert analyze(tampered, stream) == 1
