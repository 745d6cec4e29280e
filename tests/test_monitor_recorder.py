"""``odocan monitor --log`` loses nothing while its judge is slow (issue #11 rule 6).

The monitor used to read, record, judge and draw in one loop: while the judge was busy the
frames waited in the udp_multicast socket's buffer (256 frames by Linux's default) and the
kernel dropped the rest, so the log lost them too. Here a burst of ``BURST`` frames, paced as a
busy CAN bus sends them, goes onto a real udp_multicast group while the monitor's judge is held
on the first frame until the whole burst was sent: the log must hold every frame, in order, and
the judge must catch up on all of them. Checked against python-can's own ``LogReader``.

The units below: the reader's bounded queue refuses what the judge cannot take and counts it
(the log still gets it); a bus error reaches the caller after the frames read before it; the
kernel's drop count on a socket (``host.io.rxsocket``) adds up with what was read to what was
sent.
"""

from __future__ import annotations

import argparse
import json
import secrets
import socket
import threading
import time
from pathlib import Path
from typing import Any

import can
import pytest

import odocan.host.cli.subparsers.monitor as monitor_cmd
from odocan.host.cli.app import build_parser
from odocan.host.io import busreader
from odocan.host.io.buses import open_bus
from odocan.host.io.busreader import BusReader, lost_here_text
from odocan.host.io.rxsocket import SocketDrops, bus_socket_fd
from odocan.host.judge.monitor import BusMonitor
from odocan.host.report.tui_app import FrameLog, MonitorApp
from tests.test_cli_run import run_cli
from tests.udp_pair import fresh_group, open_pair

BURST = 3000  # > 10x what Linux's default receive buffer holds (256 udp_multicast frames)
PACE = 10  # frames sent back to back, then PACE_S: 2 000 frames/s, a busy 500 kbit/s bus
PACE_S = 0.005
QUIET_POLLS = 3  # the watch ends after the burst and this many empty receives in a row
UNKNOWN_ID = 0x7F0  # not in the DBC: the model counts it, nothing more


def _frame(n: int) -> can.Message:
    return can.Message(arbitration_id=UNKNOWN_ID, data=n.to_bytes(4, "little"),
                       is_extended_id=False, is_fd=False)


class _Burst:
    """Sends ``BURST`` frames once the monitor opened its bus; ``sent`` is set when done."""

    def __init__(self, group: str, port: int) -> None:
        self.args = argparse.Namespace(interface="udp_multicast", channel=group, bitrate=None,
                                       bus_arg=["hop_limit=0", f"port={port}"], faults="")
        self.opened, self.sent = threading.Event(), threading.Event()

    def run(self) -> None:
        if not self.opened.wait(60):
            return
        bus = open_bus(self.args)
        try:
            for n in range(BURST):
                bus.send(_frame(n))
                if n % PACE == PACE - 1:
                    time.sleep(PACE_S)
        finally:
            bus.shutdown()
            self.sent.set()


class _EndsAfterBurst:
    """The monitor's bus: ends the watch (``quit``, as ``q``) after the burst was sent and
    ``QUIET_POLLS`` receives in a row heard nothing; ``fileno`` passed through."""

    def __init__(self, bus: can.BusABC, burst: _Burst, app: MonitorApp) -> None:
        self.bus, self.burst, self.app = bus, burst, app
        self.quiet = 0

    def recv(self, timeout: float | None = None) -> can.Message | None:
        msg = self.bus.recv(timeout)
        self.quiet = 0 if msg is not None or not self.burst.sent.is_set() else self.quiet + 1
        if self.quiet >= QUIET_POLLS:
            self.app.quit = True
        return msg

    def fileno(self) -> int:
        return self.bus.fileno()


def _watch_burst(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
                 path: Path, held: Any) -> tuple[int, dict[str, Any], str, list[int]]:
    """``odocan monitor --log path --json`` on a fresh udp_multicast group while the burst is
    sent, ``held`` (a class and the name of its method taking one frame) held on its first
    frame until the burst was sent; (exit code, the JSON, stderr, the tags in the log)."""
    build_parser()
    group, port = fresh_group()
    burst = _Burst(group, port)
    owner, name = held
    plain = getattr(owner, name)

    def slow(self: Any, msg: can.Message, *rest: Any) -> Any:  # (a held frame's now_s)
        if not burst.sent.is_set():
            burst.sent.wait(60)  # busy for as long as the burst lasts
        return plain(self, msg, *rest)

    def open_and_start(args: Any, **overrides: Any) -> can.BusABC:
        try:
            bus = open_bus(args, **overrides)
        except Exception as exc:  # no multicast route in this sandbox
            pytest.skip(f"udp_multicast unavailable: {exc}")
        burst.opened.set()
        return bus

    class EndsAfterBurst(MonitorApp):
        def __init__(self, bus: can.BusABC, *args: Any, **kwargs: Any) -> None:
            super().__init__(_EndsAfterBurst(bus, burst, self), *args,  # type: ignore[arg-type]
                             **kwargs)

    monkeypatch.setattr(owner, name, slow)
    monkeypatch.setattr(monitor_cmd, "open_bus", open_and_start)
    monkeypatch.setattr(monitor_cmd, "MonitorApp", EndsAfterBurst)
    sender = threading.Thread(target=burst.run, name="burst")
    sender.start()
    try:
        code, out, err = run_cli(capsys, "monitor", "-i", "udp_multicast", "-c", group,
                                 "--bus-arg", "hop_limit=0", "--bus-arg", f"port={port}",
                                 "--duration", "120", "--log", str(path), "--json")
    finally:
        burst.opened.set()
        sender.join(60)
    logged = [int.from_bytes(m.data, "little") for m in can.LogReader(path)
              if m.arbitration_id == UNKNOWN_ID]
    return code, json.loads(out), err, logged


def test_the_log_holds_every_frame_of_a_burst_while_the_judge_is_held(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
) -> None:
    code, model, err, logged = _watch_burst(monkeypatch, capsys, tmp_path / "watch.log",
                                            (BusMonitor, "feed"))
    assert logged == list(range(BURST)), f"the log lost {BURST - len(logged)} of {BURST}"
    assert (code, err) == (0, "")
    assert model["frames_total"] == BURST  # the judge caught up on every frame
    assert model["receive"]["read"] == model["receive"]["recorded"] == BURST
    assert model["receive"]["judge_skipped"] == 0
    assert model["receive"]["socket_dropped"] == 0


def _tiny_buffer(bus: object, wanted_bytes: int = 0) -> int | None:
    """Instead of widening: a 4 KiB receive buffer (the kernel's minimum, a few frames)."""
    fd = bus_socket_fd(bus)
    assert fd is not None
    with socket.socket(fileno=fd) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        granted: int = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        sock.detach()  # the bus keeps its socket
    return granted


def test_frames_the_kernel_dropped_are_said_apart_and_add_up_with_the_log(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
) -> None:
    """The recorder itself held during the burst on a tiny socket buffer: the kernel drops most
    of the burst. The monitor says so on stderr and in its JSON, and what it read plus what the
    kernel dropped is every frame the sender sent; the log has exactly what was read."""
    monkeypatch.setattr(busreader, "widen_receive_buffer", _tiny_buffer)
    code, model, err, logged = _watch_burst(monkeypatch, capsys, tmp_path / "watch.log",
                                            (FrameLog, "record"))
    received = model["receive"]
    dropped = received["socket_dropped"]
    assert dropped is not None
    assert dropped > 0
    assert received["read"] + dropped == BURST
    assert received["read"] == received["recorded"] == len(logged) == model["frames_total"]
    assert logged == sorted(logged)
    assert code == 0
    assert err == (f"monitor: lost here: {dropped} frames dropped by the kernel before they "
                   f"were read (socket receive buffer of {received['socket_buffer_bytes'] >> 10}"
                   " KiB full): in neither the log nor the judge\n")


class _Virtual:
    """A python-can virtual bus pair: (the reader's, the sender's)."""

    def __init__(self, name: str) -> None:
        channel = f"{name}-{secrets.token_hex(4)}"
        self.rx, self.tx = (can.Bus(interface="virtual", channel=channel) for _ in range(2))

    def close(self) -> None:
        self.rx.shutdown()
        self.tx.shutdown()


def test_a_full_judge_queue_skips_for_the_judge_and_records_all() -> None:
    """A judge that takes nothing: the queue's ``capacity`` frames wait for it, the rest are
    counted as skipped and said, and every frame is recorded."""
    pair, recorded = _Virtual("reader-full"), list[can.Message]()
    reader = BusReader(pair.rx, recorded.append, capacity=5)
    try:
        reader.start()
        for n in range(20):
            pair.tx.send(_frame(n))
        deadline = time.monotonic() + 60
        while reader.read < 20 and time.monotonic() < deadline:
            time.sleep(0.01)
        reader.stop()
    finally:
        pair.close()
    assert [int.from_bytes(m.data, "little") for m in recorded] == list(range(20))
    assert [int.from_bytes(m.data, "little") for m in reader.drain()] == list(range(5))
    stats = reader.stats()
    assert (stats["read"], stats["judge_skipped"]) == (20, 15)
    assert stats["socket_dropped"] is None  # a virtual bus has no socket
    assert lost_here_text(stats) == "15 frames recorded but not judged (the judge fell behind)"


class _Failing:
    """Two frames, then the interface goes down."""

    def __init__(self) -> None:
        self.left = [_frame(0), _frame(1)]

    def recv(self, timeout: float | None = None) -> can.Message | None:
        if self.left:
            return self.left.pop(0)
        raise can.CanOperationError("the interface went down")


def test_a_bus_error_reaches_the_judge_after_the_frames_before_it() -> None:
    reader = BusReader(_Failing()).start()
    taken = [reader.get(10.0), reader.get(10.0)]
    assert [int.from_bytes(m.data, "little") for m in taken if m is not None] == [0, 1]
    with pytest.raises(can.CanOperationError, match="went down"):
        reader.get(60.0)  # raised once the thread failed (at once, or after its wait)
    reader.stop()


def test_the_kernel_drop_count_adds_up_with_what_was_read() -> None:
    """A udp_multicast socket with a tiny receive buffer that nobody reads: what it holds plus
    what the kernel says it dropped is every frame sent."""
    rx, tx = open_pair()
    try:
        fd = bus_socket_fd(rx)
        assert fd is not None
        with socket.socket(fileno=fd) as sock:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            sock.detach()  # the bus keeps its socket
        drops = SocketDrops(rx)
        for n in range(500):
            tx.send(_frame(n))
        heard: list[int] = []
        deadline = time.monotonic() + 60
        while len(heard) + (drops.count() or 0) < 500 and time.monotonic() < deadline:
            msg = rx.recv(0.05)
            if msg is not None:
                heard.append(int.from_bytes(msg.data, "little"))
        dropped = drops.count()
    finally:
        rx.shutdown()
        tx.shutdown()
    assert dropped is not None
    assert dropped > 0
    assert len(heard) + dropped == 500
    assert heard == sorted(heard)
