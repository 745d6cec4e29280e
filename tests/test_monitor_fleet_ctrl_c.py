"""Ctrl-C (or SIGTERM) to ``odocan monitor --broker`` while it follows the fleet.

Found from outside (trial38): once in about eight runs, a SIGINT to ``monitor --broker ...
--json`` printed asyncio's "Task exception was never retrieved ... KeyboardInterrupt" after its
verdict: the signal was raised inside the task that reads the broker, which kept it as its
exception; nobody awaited that task once the loop had stopped, and the MQTT client it had
opened was closed only as it was collected, after its loop ("Exception ignored in:
Client.__del__ ... Event loop is closed"). The watch now takes SIGINT and
SIGTERM from its event loop: it ends as at its ``--duration``, the STOPPED verdict and nothing
else said.
"""

from __future__ import annotations

import gc
import json
import signal
from collections.abc import Callable
from typing import Any

import pytest

from odocan.host.cli.app import main
from odocan.host.cli.subparsers import monitor as monitor_cmd
from tests.fleet_watch_until import BOUND_S
from tests.test_monitor_silent_broker import bare_mosquitto  # noqa: F401  (a fixture)


def _signal_once_connected(monkeypatch: pytest.MonkeyPatch, signum: int) -> None:
    """The watch raises ``signum`` at itself from the task that follows the broker, as soon as
    it has connected (as a Ctrl-C that lands while that task runs)."""

    class SignalledOnce(monitor_cmd._FleetWatch):
        async def _follow(self, redraw: Callable[[], None] | None) -> None:
            import asyncio

            follow = asyncio.ensure_future(super()._follow(redraw))
            while not self.connected_once and not follow.done():
                await asyncio.sleep(0.01)
            signal.raise_signal(signum)
            await follow

    monkeypatch.setattr(monitor_cmd, "_FleetWatch", SignalledOnce)


@pytest.mark.filterwarnings("error::pytest.PytestUnraisableExceptionWarning")
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_while_following_the_broker_ends_the_watch_cleanly(
    bare_mosquitto: str, monkeypatch: pytest.MonkeyPatch,  # noqa: F811
    capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture, signum: int,
) -> None:
    _signal_once_connected(monkeypatch, signum)
    code = main(["monitor", "--broker", bare_mosquitto, "--duration", BOUND_S, "--json"])
    gc.collect()  # a task left holding the interrupt says so as it is collected
    out, err = capsys.readouterr()
    assert not [r.getMessage() for r in caplog.records if r.name == "asyncio"]
    name = signal.Signals(signum).name
    assert err.splitlines() == [f"monitor: STOPPED by {name} at 0 s of {BOUND_S} s"], err
    said: dict[str, Any] = json.loads(out)
    assert said["robots"] == {}
    assert said["stopped"]["signal"] == name, said
    assert code == 128 + int(signum)
