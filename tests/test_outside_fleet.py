"""``odocan fleet --workers N`` stopped by Ctrl-C or SIGTERM while its workers start.

Found from outside: SIGTERM 1.5 s after ``odocan fleet -n 4 --workers 2`` started ended with
``error: fleet worker 0 ended without a report (exit code -15)`` and exit 2 -- blaming a worker
for the signal the parent had passed on to it before its handlers were in place. It is the
interruption (exit 130/143 from ``main``); a worker that dies by itself is still an error.
"""

from __future__ import annotations

import signal
import time
from dataclasses import dataclass

import pytest

from odocan.host.mqtt import shards
from odocan.sim.exceptions import OdocanError, Terminated


@dataclass
class _Ended:
    """A worker process that has ended with ``exitcode``."""

    exitcode: int

    def is_alive(self) -> bool:
        return False


FAR = time.monotonic() + 3600


@pytest.mark.parametrize(
    ("passed_on", "raised"),
    [([signal.SIGTERM], Terminated), ([signal.SIGINT], KeyboardInterrupt)],
)
def test_a_worker_stopped_by_the_passed_on_signal_is_the_interruption(
    passed_on: list[int], raised: type[BaseException]
) -> None:
    with pytest.raises(raised):
        shards._check_alive([_Ended(-signal.SIGTERM)], {}, FAR, passed_on)


def test_sigint_is_not_taken_for_sigterm() -> None:
    with pytest.raises(KeyboardInterrupt) as caught:
        shards._check_alive([_Ended(-signal.SIGTERM)], {}, FAR, [signal.SIGINT])
    assert not isinstance(caught.value, Terminated)


@pytest.mark.parametrize(
    ("exitcode", "passed_on"),
    [(-signal.SIGTERM, []), (-signal.SIGKILL, [signal.SIGTERM]), (1, [signal.SIGTERM])],
)
def test_a_worker_that_died_otherwise_is_still_an_error(
    exitcode: int, passed_on: list[int]
) -> None:
    with pytest.raises(OdocanError, match=f"fleet worker 0 ended without a report \\(exit code "
                       f"{exitcode}\\)"):
        shards._check_alive([_Ended(exitcode)], {}, FAR, passed_on)
