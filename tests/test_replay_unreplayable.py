"""``odocan replay`` of a log whose firmware lived what a lockstep replay cannot reproduce.

A replay runs one firmware life from the log's first encoder frame and feeds, one per tick, the
encoder frames the host's E2E check accepts. A log with a firmware reboot (two drives recorded
one after the other), or with encoder frames that came late and out of sequence (``--faults
delay=``), departs from the replay although the firmware build is the same: the FAIL may stand
(the replay does depart), but its reason must name what the replay could not reproduce, never
"the firmware build differs" (found in a user trial: both logs below said so).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from odocan.host.cli.app import main
from tests.test_cli_run import run_cli

BUILD_DIFFERS = "the firmware build differs"


def _run(log: Path, *extra: str) -> None:
    assert main(["run", "--robot", "kobuki", "--duration", "10", "--log", str(log),
                 *extra]) == 0


def _rebooted_log(folder: Path) -> Path:
    """Two 10 s drives, the second recorded after the first (times shifted by 11 s)."""
    first, second = folder / "first.log", folder / "second.log"
    _run(first, "--seed", "1")
    _run(second, "--seed", "2")
    both = folder / "rebooted.log"
    lines = first.read_text().splitlines(keepends=True)
    for line in second.read_text().splitlines(keepends=True):
        stamp, rest = line.split(" ", 1)
        lines.append(f"({float(stamp[1:-1]) + 11.0:.6f}) {rest}")
    both.write_text("".join(lines))
    return both


def test_a_reboot_in_the_log_is_named_not_the_build(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The second drive 1 s after the first: the log has a hole there, so the replay compares
    its poses from the first frame both name after it (``host.judge.replay_compare``), where
    the same build follows the log's rebooted firmware again: it says so, and never blames the
    build (it was FAIL, 'the firmware build differs', in a user trial; then FAIL naming the
    reboot)."""
    log = _rebooted_log(tmp_path)
    assert main(["analyze", str(log), "--robot", "kobuki"]) == 0  # the log itself is right
    code, out, _ = run_cli(capsys, "replay", str(log), "--robot", "kobuki")
    assert BUILD_DIFFERS not in out
    assert code == 0, out
    assert "replay: the log has a hole at t=9.99 s (1.01 s without a frame)" in out


def test_late_encoder_frames_are_named_not_the_build(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Since the rig puts held frames on the bus at their release time, a 10 % share held 15 ms
    replays faithfully; a 20 % share makes the recording firmware take late frames, which the
    replay now feeds where they arrived (``replay_track.late_frames``): it compares the
    positions after the first gap by their drift, PASSes, and never blames the build. It
    FAILed on 383.5 mrad of heading (and the log's own
    "resent" poses 16.8 mm apart) until a pose could no longer name a frame logged after it
    (``EncoderTrack.named``): those were poses put at the wrong frame, not departures."""
    log = tmp_path / "late.log"
    _run(log, "--seed", "1", "--faults", "delay=0.2:15,seed=1")
    capsys.readouterr()
    code, out, _ = run_cli(capsys, "replay", str(log), "--robot", "kobuki")
    assert BUILD_DIFFERS not in out
    assert "after it by their position drift between gaps (max 0.0000 mm); " \
        "heading 0.0000 mrad" in out, out
    assert code == 0, out
