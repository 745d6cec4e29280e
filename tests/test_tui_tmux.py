"""``odocan monitor`` as a person sees it: a process of its own in an 80×24 tmux pane.

The test process runs the lockstep rig paced to the wall clock and forwards every frame to a
loopback-only ``udp_multicast`` channel (a unique group and port, hop limit 0, as in
``test_realtime``); ``python -m odocan monitor`` listens to it inside ``tmux new-session -d -x 80
-y 24`` on a tmux server of the test's own (``-L``). ``capture-pane -p`` reads the screen,
``send-keys`` pauses and quits. Checked on the 24 rows: the firmware line and the three pose
rows while frames flow, PAUSED after ``p``, the silence warning and STALE once the sender stops,
and exit code 0 after ``q``.

``python -m tests.tui_screenshots`` drives the same pane to make the README's screenshots.
"""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import can
import pytest

from odocan.sim import robot
from odocan.sim.faults import FaultSpec
from odocan.sim.rig import LockstepRig, RigConfig
from tests.requires import require_executables
from tests.test_realtime import _open_udp_or_skip, _udp_channel

ROOT = Path(__file__).resolve().parent.parent
START_TIMEOUT_S = 30.0  # imports and the first frames on a loaded 2-core machine
COLUMNS, ROWS = 80, 24


@dataclass
class Sender:
    """The lockstep rig at wall-clock pace, every host-bus frame sent to ``bus``."""

    bus: can.BusABC
    faults: str = ""
    seed: int = 2
    stop: threading.Event = field(default_factory=threading.Event)
    sent: int = 0
    thread: threading.Thread | None = None

    def start(self) -> None:
        """Run in a thread until ``stop`` is set (or 120 s of driving)."""
        self.thread = threading.Thread(target=self._run, name="udp-sender", daemon=True)
        self.thread.start()

    def _run(self) -> None:
        sender = self

        class Forward(can.Listener):
            def on_message_received(self, msg: can.Message) -> None:
                sender.bus.send(msg)
                sender.sent += 1

        config = RigConfig(robot=robot.load("pmir"), seed=self.seed,
                           channel=f"tmux-rig-{os.getpid()}-{id(self)}", duration_s=120.0,
                           faults=FaultSpec.parse(self.faults) if self.faults else None)
        with LockstepRig(config, listeners=[Forward()]) as rig:
            t0 = time.monotonic()
            for k in range(12_000):
                if self.stop.is_set():
                    return
                rig.step()
                time.sleep(max(0.0, t0 + (k + 1) * 0.01 - time.monotonic()))

    def halt(self) -> None:
        """Stop sending and wait for the thread."""
        self.stop.set()
        if self.thread is not None:
            self.thread.join(10)


class Pane:
    """One 80×24 tmux pane on a tmux server of its own, running one command."""

    def __init__(self, command: str) -> None:
        self.socket = f"odocan-tui-{os.getpid()}-{time.monotonic_ns()}"
        self._tmux("new-session", "-d", "-x", str(COLUMNS), "-y", str(ROWS), "-s", "tui",
                   command)

    def _tmux(self, *args: str) -> str:
        done = subprocess.run(["tmux", "-L", self.socket, *args], capture_output=True,
                              text=True, timeout=20, check=False)
        if done.returncode != 0:
            raise RuntimeError(f"tmux {args[0]}: {done.stderr.strip()}")
        return done.stdout

    def rows(self, *, ansi: bool = False) -> list[str]:
        """The visible rows (with colour escapes when ``ansi``)."""
        out = self._tmux("capture-pane", "-p", *(["-e"] if ansi else []), "-t", "tui")
        rows = out.rstrip("\n").split("\n")
        assert len(rows) <= ROWS, out
        return rows + [""] * (ROWS - len(rows))  # tmux leaves out the empty rows at the bottom

    def keys(self, *keys: str) -> None:
        """Type ``keys`` (tmux key names: "p", "Space", "q")."""
        self._tmux("send-keys", "-t", "tui", *keys)

    def wait_for(self, check: Callable[[list[str]], bool], timeout_s: float) -> list[str]:
        """Poll the screen until ``check(rows)``; the last screen in the failure message."""
        deadline = time.monotonic() + timeout_s
        while True:
            rows = self.rows()
            if check(rows):
                return rows
            if time.monotonic() > deadline:
                raise AssertionError("screen never matched:\n" + "\n".join(rows))
            time.sleep(0.2)

    def close(self) -> None:
        """Kill this test's own tmux server (and the monitor in it)."""
        subprocess.run(["tmux", "-L", self.socket, "kill-server"], capture_output=True,
                       timeout=20, check=False)


def monitor_command(bus_argv: list[str], *extra: str) -> str:
    """The shell command of the pane: the monitor, then its exit code, then a pause to read it."""
    env = f"PYTHONPATH={shlex.quote(os.environ.get('PYTHONPATH', str(ROOT)))}"
    argv = [sys.executable, "-m", "odocan", "monitor", *bus_argv, *extra]
    return (f"cd {shlex.quote(str(ROOT))} && env {env} TERM=xterm-256color "
            f"{shlex.join(argv)}; echo EXIT=$?; sleep 30")


@pytest.fixture
def udp() -> Iterator[tuple[list[str], can.BusABC]]:
    """CLI options of a fresh loopback udp_multicast channel, and the sender's bus on it."""
    require_executables("tmux", install="apt-get install tmux")
    argv, kwargs = _udp_channel()
    bus = _open_udp_or_skip(kwargs)
    try:
        yield argv, bus
    finally:
        bus.shutdown()


def healthy_rows(rows: list[str]) -> bool:
    """The verdict and firmware OK lines and three pose rows with numbers, within 24 rows."""
    return (rows[1].startswith("verdict OK") and rows[2].startswith("firmware OK")
            and [r.split()[0] for r in rows[4:7] if r.split()] == ["on-board", "reference",
                                                                   "truth"]
            and all(len(r.split()) >= 8 and r.split()[1] != "-" for r in rows[4:7]))


def test_monitor_in_tmux_at_80x24(udp: tuple[list[str], Any]) -> None:
    argv, bus = udp
    sender = Sender(bus)
    pane = Pane(monitor_command(argv))
    try:
        sender.start()
        rows = pane.wait_for(healthy_rows, START_TIMEOUT_S)
        assert rows[0].startswith("odocan monitor udp_multicast:")
        assert any(r.startswith("WHEEL_ENCODERS 0x100") for r in rows[8:13])
        assert rows[-1].startswith("space/p pause")

        pane.keys("p")
        pane.wait_for(lambda r: "PAUSED" in r[0] and "trace (paused" in "\n".join(r), 10)
        pane.keys("Space")
        rows = pane.wait_for(lambda r: "PAUSED" not in r[0], 10)
        assert healthy_rows(rows)

        sender.halt()
        rows = pane.wait_for(lambda r: "since the last frame: the sender stopped" in r[7], 15)
        assert rows[1].startswith("verdict STALE: ODOM_MCU silent for")
        assert "STALE" in rows[2]  # the status is older than 2 s
        assert [r.split()[0] for r in rows[4:7]] == ["on-board", "reference", "truth"]

        pane.keys("q")
        pane.wait_for(lambda r: any(line.startswith("EXIT=0") for line in r), 15)
    finally:
        sender.halt()
        pane.close()


def test_a_virtual_bus_in_a_process_of_its_own_says_why_it_hears_nothing() -> None:
    """The issue's trap: ``-i virtual`` alone in its process hears nothing, and now says why."""
    require_executables("tmux", install="apt-get install tmux")
    pane = Pane(monitor_command(["-i", "virtual", "-c", f"vcan-alone-{os.getpid()}"]))
    try:
        rows = pane.wait_for(lambda r: r[7].startswith("nothing heard for"), START_TIMEOUT_S)
        assert "virtual bus lives inside one process" in rows[7]
        assert rows[1].startswith("verdict NO FIRMWARE")
        assert rows[2].startswith("firmware no ODOM_STATUS summary yet")
        pane.keys("q")
        pane.wait_for(lambda r: any(line.startswith("EXIT=0") for line in r), 15)
    finally:
        pane.close()
