"""The first count page after a re-primed power-up pins the re-prime's frames (issue #11;
``host.judge.reprimecount``): its ENC_E2E_LOST is the E2E counter's step into the frame the
firmware re-primed on from the last frame its FIFO kept, ``(r - f - 1) mod 16``.

The rig of ``tests.test_reprimed_power_up_moving`` (pmir on the circle, powered up at 5 s while
it drives, halted 4.5 / 6 / 10 s). The float64 checker there (cantools-decoded frames) shows the
firmware primed on frame 1, stepped frame 2 and re-primed on the resumed frame (``halted + 2``).
Before, ``analyze`` chose the pair (2, halted - 4) at 10 s (its re-prime event on frame 996),
a pair the firmware's own count contradicts (LOST 7, the pair's 1); now it names the frame the
checker finds.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from odocan.firmware import frames as fr
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import POSITION_LSB_M, analyze
from tests.test_first_second_reboot import _decoded, _written
from tests.test_reprimed_power_up_moving import _off_m, drive
from tests.test_stall_beyond_window import PMIR


@pytest.mark.parametrize("halted", [450, 600, 1000])
def test_the_count_page_names_the_frame_it_reprimed_on(halted: int, tmp_path: Path) -> None:
    messages = drive(halted)
    resumed = halted + 2  # the checker's: primed on 1, stepped 2, re-primed on the resumed
    assert _off_m(messages, halted, 1) <= POSITION_LSB_M
    pages = [_decoded(m) for m in messages if m.arbitration_id == fr.ODOM_STATUS_ID]
    lost = next(int(p["ENC_E2E_LOST"]) for p in pages if "ENC_E2E_LOST" in p)
    assert (resumed - 2 - 1) % 16 == lost  # the page's value: f = 2, r = resumed
    analysis = analyze(read_log(_written(messages, tmp_path / "right.log")), PMIR, "exact")
    assert analysis.passed
    frames = [e["encoder_frame"] for e in analysis.report["events"]
              if e["kind"] == "stall_reprime"]
    assert frames == [resumed]
