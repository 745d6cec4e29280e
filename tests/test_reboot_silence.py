"""A reboot inside a bus-off whose power-up nothing on the log names (issue #11 item 5).

The firmware reset inside a bus-off of 0.5..2 s; the recorder then missed its first summaries
and every page of WHEEL_ENCODERS E2E counts (ENC_E2E_OK, the page that names the frame it primed
on). ``reboots.split_lives`` (and ``stream_lives``) cut the new life at the first summary heard:
the new firmware's poses heard between the bus's return and that summary fell in the old life
and a correct firmware FAILed (kobuki ``--seed 5 --faults busoff=4:1,reboot=4.3``, count pages
gone: 45.7 mm and 6.3 rad off), and a first summary of UPTIME 1 had the new life's start fitted.
Now the life starts after the silence and is judged from (0, 0, 0) on each frame it may have
primed on (``host.judge.silentboot``): the correct firmware PASSes, whole and streamed, and the
same log with ODOM_POSE_X raised by 10 mm after the reboot (E2E CRC recomputed by cantools,
``tests.log_edit.raise_raw``) FAILs: no frame it may have primed on absorbs the offset.

The drives are the CLI's own (``odocan run``); the edits are made here with python-can and
cantools, the page told by the DBC (the multiplexer value of ENC_E2E_OK).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import can
import cantools
import pytest
from cantools.database.can import Database

from odocan.sim import contract
from tests.judges_cli import raise_x_10_mm

DRIVES = [  # (robot, seed, bus-off start s, its length s, reset s, first summaries missed)
    ("kobuki", 5, 4.0, 1.0, 4.3, 0),
    ("kobuki", 5, 4.0, 1.0, 4.3, 8),
    ("kobuki", 9, 4.0, 2.0, 5.0, 8),
    ("pmir", 5, 4.0, 0.5, 4.2, 0),
    ("pmir", 9, 4.0, 1.5, 4.9, 8),
]


def _cli(*args: str) -> int:
    done = subprocess.run([sys.executable, "-m", "odocan", *args], capture_output=True,
                          text=True, timeout=600, check=False)
    assert "Traceback" not in done.stderr, done.stderr
    return done.returncode


def _strip(src: Path, dst: Path, from_s: float, summaries: int) -> int:
    """``src`` copied to ``dst`` without any count page from ``from_s`` s after its first frame
    on, nor the first ``summaries`` other ODOM_STATUS frames from there; frames dropped."""
    db = cantools.database.load_file(str(contract.DBC_PATH))
    assert isinstance(db, Database)
    status = db.get_message_by_name("ODOM_STATUS")
    ids = status.get_signal_by_name("ENC_E2E_OK").multiplexer_ids
    assert ids is not None
    page = ids[0]
    dropped, skipped, first = 0, 0, None
    with can.Logger(str(dst)) as out:
        for msg in can.LogReader(str(src)):
            first = msg.timestamp if first is None else first
            if msg.arbitration_id == status.frame_id and msg.timestamp - first >= from_s:
                decoded = status.decode(bytes(msg.data), decode_choices=False)
                assert isinstance(decoded, dict)
                if decoded["PAGE"] == page or skipped < summaries:
                    dropped += 1
                    skipped += decoded["PAGE"] != page
                    continue
            out.on_message_received(msg)
    return dropped


@pytest.mark.parametrize(("robot", "seed", "off_s", "length_s", "reset_s", "summaries"), DRIVES)
def test_a_reboot_in_a_bus_off_nothing_names_is_judged_from_its_power_up(
        robot: str, seed: int, off_s: float, length_s: float, reset_s: float, summaries: int,
        tmp_path: Path) -> None:
    drive, log, tampered = tmp_path / "drive.log", tmp_path / "log.log", tmp_path / "t.log"
    assert _cli("run", "--robot", robot, "--seed", str(seed), "--duration", "8", "--faults",
                f"busoff={off_s}:{length_s},reboot={reset_s}", "--log", str(drive)) == 0
    back_s = off_s + length_s - 0.05  # just before the bus's return: every page after it
    assert _strip(drive, log, back_s, summaries) >= summaries + 3
    for stream in ("always", "never"):
        assert _cli("analyze", str(log), "--stream", stream) == 0, stream
    assert raise_x_10_mm(log, tampered, back_s) > 50
    for stream in ("always", "never"):
        assert _cli("analyze", str(tampered), "--stream", stream) == 1, stream


@pytest.mark.parametrize("summaries", [8, 0])
def test_the_live_judges_follow_a_reboot_in_a_bus_off_nothing_names(
        summaries: int, tmp_path: Path) -> None:
    """The monitor and the bridge (``host.judge.livesilentboot``). Kobuki ``--seed 5
    busoff=4:1,reboot=4.3``, count pages missed: with the 8 first summaries missed too (the
    first heard says UPTIME 1 s) they judged the new firmware's poses against the old life's
    reference placed across the bus-off, then adopted the next pose: the correct firmware
    4.43 mm off, the one 10 mm off the same 4.43 mm; with none missed (UPTIME 0) the life
    started on the latest frame at the summary, 0.1 s after its first pose: 45.67 mm. Now the
    life starts at (0, 0, 0) on the frame after the bus-off that agrees best with the first pose
    (``silentboot``'s candidates), the poses before its summary withdrawn: 0.07 mm, and the
    tampered log FAILs by 12.3 mm."""
    from odocan.host.judge.analysis import POSITION_LSB_M
    from tests.test_live_reboot import bridge_of, monitor_of

    drive, log, tampered = tmp_path / "drive.log", tmp_path / "log.log", tmp_path / "t.log"
    assert _cli("run", "--robot", "kobuki", "--seed", "5", "--duration", "8", "--faults",
                "busoff=4:1,reboot=4.3", "--log", str(drive)) == 0
    assert _strip(drive, log, 4.95, summaries) >= summaries + 3
    assert raise_x_10_mm(log, tampered, 4.95) > 50
    for judge in (monitor_of, bridge_of):
        right = judge(log, "kobuki", "exact").tracker.vs_reference.max_dpos_m
        wrong = judge(tampered, "kobuki", "exact").tracker.vs_reference.max_dpos_m
        assert right <= POSITION_LSB_M < 50 * POSITION_LSB_M < wrong, (judge, right, wrong)
