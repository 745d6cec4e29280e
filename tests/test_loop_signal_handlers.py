"""``sim.interrupts.loop_handlers_installed``: SIGINT and SIGTERM are an event loop's while a
watch, a bridge or a fleet runs, and the CLI's latching handlers come back after (asyncio's own
removal leaves Python's default for SIGINT and SIG_DFL for SIGTERM: a SIGTERM as the command
wrote its verdict then killed it, -15, instead of its one line and 143)."""

from __future__ import annotations

import asyncio
import signal
import threading
from collections.abc import Iterator

import pytest

from odocan.sim import interrupts


@pytest.fixture
def cli_handlers() -> Iterator[object]:
    """The CLI's handler on both signals while the test runs, the previous ones back after."""
    with interrupts.handlers_installed({s: interrupts.latch_and_raise
                                        for s in (signal.SIGINT, signal.SIGTERM)}):
        yield interrupts.latch_and_raise
    interrupts.clear()


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_the_loop_hears_the_signal_and_the_clis_handler_is_back_after(
    cli_handlers: object, signum: signal.Signals,
) -> None:
    heard: list[int] = []

    async def watch() -> None:
        with interrupts.loop_handlers_installed(asyncio.get_running_loop(), heard.append):
            assert signal.getsignal(signum) is not cli_handlers
            signal.raise_signal(signum)
            for _ in range(100):  # the loop calls back on its next turns
                if heard:
                    break
                await asyncio.sleep(0.01)

    asyncio.run(watch())
    assert heard == [int(signum)]
    assert interrupts.latched() is None  # a request to the loop, not a latched interruption
    assert signal.getsignal(signal.SIGINT) is cli_handlers
    assert signal.getsignal(signal.SIGTERM) is cli_handlers


def test_outside_the_main_thread_nothing_is_installed(cli_handlers: object) -> None:
    entered: list[bool] = []

    def elsewhere() -> None:
        async def watch() -> None:
            with interrupts.loop_handlers_installed(asyncio.get_running_loop(), print):
                entered.append(True)

        asyncio.run(watch())

    thread = threading.Thread(target=elsewhere)
    thread.start()
    thread.join(10)
    assert entered == [True]
    assert signal.getsignal(signal.SIGTERM) is cli_handlers
