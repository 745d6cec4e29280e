"""When a count page was sent, from the next ODOM_STATUS frame heard (``host.judge.pagesent``;
issue #11, kobuki figure8 672 in ``tests/test_run_delay_stall.py``)."""

from __future__ import annotations

import numpy as np
import pytest

from odocan.host.judge.pagesent import counted_from, sent_s


@pytest.mark.parametrize(
    ("following", "sent"),
    [
        ((2.201, 4), 2.101),  # figure8 672: the next tick's summary heard on time
        ((2.202, 5), 2.102),  # its page (the summary lost)
        ((2.256, 4), 2.156),  # as late as the page: no earlier
        ((2.301, 6), 2.156),  # three steps on: two ticks or more, not told
        ((2.180, 0), 2.156),  # a new firmware's power-up summary: another sequence
        ((2.180, 1), 2.156),  # ... its power-up page
        (None, 2.156),  # nothing heard after it (the log's end)
    ],
)
def test_the_send_is_bounded_by_the_next_tick(
    following: tuple[float, int] | None, sent: float
) -> None:
    """The count page COUNTER 3 heard at 2.156 s: sent a status cycle or more before the next
    tick's frame, never after it was heard."""
    assert sent_s((2.156, 3), following) == pytest.approx(sent)


def test_a_page_on_time_stays() -> None:
    assert sent_s((2.101, 3), (2.201, 4)) == pytest.approx(2.101)


def test_counted_from_the_first_encoder_frame_sent_after_it() -> None:
    """Encoder frames every 10 ms to 2.150 s, the page heard at 2.156 s (position 10), sent at
    2.101 s: counted from the frame of 2.110 s (the latest before it, 2.100 s, the firmware's
    last); sent when heard: the page's own position."""
    at = np.arange(0, 20, 2, dtype=np.int64)  # positions 0, 2, .. 18
    t_s = (2.06 + 0.01 * np.arange(10)).astype(np.float64)
    assert counted_from(19, 2.101, (at, t_s)) == 10
    assert counted_from(19, 2.156, (at, t_s)) == 19
    assert counted_from(9, 2.101, (at, t_s)) == 9  # frames before position 9 end at 2.10 s
