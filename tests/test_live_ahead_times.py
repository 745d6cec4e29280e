"""The live judges' "names ahead" line counts its times from the drive's first frame, as their
other lines do (trial40: the monitor printed a live bus's raw epoch stamps, "ODOM_POSE_X at
1765000000.161000 s names ..."). The log of ``test_names_ahead``'s tamper, every stamp moved
1.7e9 s on (a live recorder's clock): the line says the times of the drive."""

from __future__ import annotations

from pathlib import Path

import can
import pytest

from odocan.host.cli.app import main
from tests.judges_cli import TEN_MM_LSB, live_judges
from tests.test_names_ahead import name_ahead, named_before_sent

EPOCH_S = 1.7e9


@pytest.fixture(scope="module")
def tampered(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 10 s square drive, poses 100..349 naming a frame not yet sent, X 10 mm off."""
    work = tmp_path_factory.mktemp("aheadtimes")
    log = work / "base.log"
    assert main(["run", "--scenario", "square", "--duration", "10", "--log", str(log)]) == 0
    out = work / "ahead.log"
    assert name_ahead(log, out, 100, 349, 1, TEN_MM_LSB) == 250
    return out


def test_the_names_ahead_line_counts_from_the_drive_start(tampered: Path,
                                                          tmp_path: Path) -> None:
    frames = list(can.LogReader(str(tampered)))
    first_s = frames[0].timestamp
    moved = tmp_path / "epoch.log"
    with can.Logger(str(moved)) as out:
        for msg in frames:
            out.on_message_received(can.Message(
                timestamp=msg.timestamp + EPOCH_S, arbitration_id=msg.arbitration_id,
                data=msg.data, is_extended_id=msg.is_extended_id, is_rx=msg.is_rx))
    pose, t_s, sent_s = min(named_before_sent(tampered), key=lambda f: (f[1], f[0]))
    said = (f"{pose} at {t_s - first_s:.6f} s names WHEEL_ENCODERS COUNTER")
    until = f"not sent until {sent_s - first_s:.6f} s"
    monitor, bridge = live_judges("pmir", moved)
    for judge in (monitor, bridge):
        why = judge.ahead.why()
        assert len(why) == 1, why
        assert said in why[0], why
        assert until in why[0], why
