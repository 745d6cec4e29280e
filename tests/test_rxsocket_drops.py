"""The kernel's count of the frames it dropped on a bus's socket, read from the socket itself
(``SO_MEMINFO``), so that ``socketcan``'s drops are known too (they were "unknown": only
``/proc/net/udp`` was read, which lists no CAN_RAW socket).

Each test fills a tiny receive buffer that nobody reads: what the socket holds plus the count
is every frame sent. The UDP test checks the count against ``/proc/net/udp`` parsed here; the
SocketCAN test needs a ``vcan0`` (``ip link add dev vcan0 type vcan``) and skips without one.
"""

from __future__ import annotations

import os
import socket
from pathlib import Path

import can
import pytest

from odocan.host.io.rxsocket import SocketDrops, bus_socket_fd
from tests.test_monitor_recorder import _frame
from tests.udp_pair import open_pair

SENT = 500
QUIET_POLLS = 3  # empty receives in a row: the socket is drained
VCAN = "vcan0"


def _shrink(bus: can.BusABC) -> None:
    """A 4 KiB receive buffer (the kernel's minimum: a few frames)."""
    fd = bus_socket_fd(bus)
    assert fd is not None
    with socket.socket(fileno=fd) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.detach()  # the bus keeps its socket


def _proc_udp_drops(bus: can.BusABC) -> int:
    """The ``drops`` column of the bus's socket's line in ``/proc/net/udp``, parsed here."""
    fd = bus_socket_fd(bus)
    assert fd is not None
    inode = str(os.fstat(fd).st_ino)
    for line in Path("/proc/net/udp").read_text().splitlines()[1:]:
        fields = line.split()
        if fields[9] == inode:
            return int(fields[12])
    pytest.skip("/proc/net/udp does not list the socket")


def _fill_and_count(rx: can.BusABC, tx: can.BusABC, drops: SocketDrops) -> tuple[list[int], int]:
    """``SENT`` frames onto a shrunk ``rx``, then what it held (in order) and the count."""
    _shrink(rx)
    for n in range(SENT):
        tx.send(_frame(n))
    heard: list[int] = []
    quiet = 0
    while quiet < QUIET_POLLS:  # every frame was sent: the socket holds what it kept
        msg = rx.recv(0.05)
        quiet = 0 if msg is not None else quiet + 1
        if msg is not None:
            heard.append(int.from_bytes(msg.data, "little"))
    dropped = drops.count()
    assert dropped is not None, "the kernel's drop count was not read"
    return heard, dropped


def test_the_drop_count_is_read_from_the_socket_itself() -> None:
    """No ``/proc`` table given: the count comes from the socket, and it is the one
    ``/proc/net/udp`` shows."""
    rx, tx = open_pair()
    try:
        heard, dropped = _fill_and_count(rx, tx, SocketDrops(rx, tables=()))
        in_proc = _proc_udp_drops(rx)
    finally:
        rx.shutdown()
        tx.shutdown()
    assert dropped > 0
    assert dropped == in_proc
    assert len(heard) + dropped == SENT
    assert heard == sorted(heard)


def test_socketcan_drops_are_counted() -> None:
    if not Path(f"/sys/class/net/{VCAN}").exists():
        pytest.skip(f"no {VCAN} (ip link add dev {VCAN} type vcan; ip link set up {VCAN})")
    try:
        rx = can.Bus(interface="socketcan", channel=VCAN)
        tx = can.Bus(interface="socketcan", channel=VCAN)
    except Exception as exc:
        pytest.skip(f"socketcan on {VCAN} unavailable: {exc}")
    try:
        heard, dropped = _fill_and_count(rx, tx, SocketDrops(rx))
    finally:
        rx.shutdown()
        tx.shutdown()
    assert dropped > 0
    assert len(heard) + dropped == SENT
    assert heard == sorted(heard)
