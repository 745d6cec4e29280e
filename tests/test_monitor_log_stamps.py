"""``monitor --log`` writes stamps that never go back (issue #11's last note).

The monitor's recordings had 1 us timestamp inversions (the receive stamps of the frames its
reader thread reads), which ``analyze`` then warned about ("N frames earlier than the frame
before"). ``FrameLog`` writes a frame stamped earlier than the one before with that one's stamp;
read back with python-can's own readers, each format's stamps are non-decreasing and every frame
is there, in order, with its bytes."""

from __future__ import annotations

from itertools import pairwise
from pathlib import Path

import can
import pytest

from odocan.host.report.tui_app import FrameLog

STAMPS_S = [100.000001, 100.000003, 100.000002, 100.000004, 100.000004, 100.000001, 100.00001]


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf"])
def test_recorded_stamps_never_go_back(tmp_path: Path, suffix: str) -> None:
    sent = [can.Message(timestamp=t_s, arbitration_id=0x100 + k, data=bytes([k] * 8),
                        is_extended_id=False) for k, t_s in enumerate(STAMPS_S)]
    path = tmp_path / f"watch{suffix}"
    recorder = FrameLog(path)
    for msg in sent:
        recorder.record(msg)
    recorder.close()
    assert [m.timestamp for m in sent] == STAMPS_S  # the frames handed to the judge: untouched
    with can.LogReader(str(path)) as reader:
        got = list(reader)
    assert [(m.arbitration_id, bytes(m.data)) for m in got] == [
        (m.arbitration_id, bytes(m.data)) for m in sent]
    stamps = [m.timestamp for m in got]
    assert all(b >= a for a, b in pairwise(stamps)), stamps
    assert stamps[-1] - stamps[0] == pytest.approx(STAMPS_S[-1] - STAMPS_S[0], abs=2e-6)  # .asc
    # and .blf read back relative to the first frame
    assert recorder.stamps_raised == 2
