"""The live DISTANCE judge's lossy spans (``livedistance.lost_on_board``): an ENC_E2E page opens
one only where ENC_E2E_LOST grew beyond the bus's own gaps since the page before, as
``analyze``'s ``losses.firmware_losses`` (``lost_beyond_gaps``). Before, any growth did: under
``delay=0.2:40,stall=2:0.1`` every page's grew by the bus's gaps, and the fine path of those
spans let a DISTANCE 10 mm low PASS live (``tests/test_live_swappedskips.py``)."""

from __future__ import annotations

import pytest

from odocan.host.judge.livedistance import lost_on_board


@pytest.mark.parametrize(("before", "after", "frames", "bus_gaps", "lost"), [
    ((3, 100), (3, 160), 60, 0, False),  # nothing lost
    ((3, 100), (7, 156), 56, 4, False),  # the 4 the bus lacked too
    ((3, 100), (8, 155), 56, 4, True),  # one more: a frame the bus carried
    ((250, 100), (4, 154), 56, 10, False),  # ENC_E2E_LOST wrapped: 10 grown, the bus's 10
    ((3, 100), (3, 100), 300, 0, True),  # 256 lost (a lap): ENC_E2E_OK grew by none of 300
    ((3, 100), (5, 100), 0, 2, False),  # no frame taken between the pages: no span
])
def test_a_page_is_lossy_only_beyond_the_bus_gaps(before: tuple[int, int],
                                                  after: tuple[int, int], frames: int,
                                                  bus_gaps: int, lost: bool) -> None:
    """(ENC_E2E_LOST, ENC_E2E_OK) at two pages, the frames the host took between them and the
    sender's periods the bus lacked: lossy exactly when the firmware lost more."""
    assert lost_on_board(before, after, frames, bus_gaps) is lost
