"""The kernel socket under a live bus: a wide receive buffer, and what the kernel dropped.

A python-can bus over a socket (``udp_multicast``, ``socketcan``) is read by the process that
opened it; while that process is not scheduled (a loaded laptop, a busy judge) the frames wait
in the socket's receive buffer, and the kernel drops every frame that arrives when it is full.
Linux's default (``net.core.rmem_default``, 208 KiB) holds 256 udp_multicast frames: 0.7 s of
the rig's 360 frames/s. ``widen_receive_buffer`` asks for ``RECEIVE_BUFFER_BYTES`` (the kernel
grants up to ``net.core.rmem_max``, doubled for its bookkeeping: 8 MiB, about 10 000 frames,
here), as candump users do with ``-r``. ``SocketDrops`` reads the kernel's own count of the frames
it dropped on that socket (its ``sk_drops``): by ``getsockopt(SO_MEMINFO)`` (Linux >= 4.12),
which answers for any socket, a CAN_RAW one (``socketcan``) as a UDP one; else from
``/proc/net/udp``'s ``drops`` column (the same count, UDP only); None for a bus without a socket.
SocketCAN's own ``SO_RXQ_OVFL`` carries the same count as ancillary data of each ``recvmsg``,
which python-can 4's ``socketcan`` bus does not ask room for (one timestamp only): not usable.

Both work on a duplicate of the bus's ``fileno()`` (python-can's public API), never on an
interface's private socket object.
"""

from __future__ import annotations

import contextlib
import os
import socket
import stat
import struct
from pathlib import Path

RECEIVE_BUFFER_BYTES = 8 << 20  # asked for; the kernel caps it at net.core.rmem_max (x2)
UDP_TABLES = (Path("/proc/net/udp"), Path("/proc/net/udp6"))
_DROPS_COLUMN = 12  # sl local rem st tx:rx tr:when retr uid timeout inode ref pointer drops
_INODE_COLUMN = 9
SO_MEMINFO = getattr(socket, "SO_MEMINFO", 55)  # <asm-generic/socket.h>; Linux >= 4.12
_MEMINFO = struct.Struct("=9I")  # u32 sk_meminfo[SK_MEMINFO_VARS] (<linux/sock_diag.h>)
_MEMINFO_DROPS = 8  # SK_MEMINFO_DROPS


def bus_socket_fd(bus: object) -> int | None:
    """The socket file descriptor of a bus (``can.BusABC.fileno``), or None (a bus without a
    ``fileno``, or not a socket)."""
    fileno = getattr(bus, "fileno", None)
    try:
        fd = fileno() if callable(fileno) else -1
    except (NotImplementedError, OSError, ValueError):
        return None
    if not isinstance(fd, int):
        return None
    try:
        return fd if fd >= 0 and stat.S_ISSOCK(os.fstat(fd).st_mode) else None
    except OSError:
        return None


def widen_receive_buffer(bus: object, wanted_bytes: int = RECEIVE_BUFFER_BYTES) -> int | None:
    """Ask the kernel for a ``wanted_bytes`` receive buffer on the bus's socket (never smaller
    than it is); returns the size the kernel granted (bytes, its bookkeeping included), or None
    for a bus without a socket."""
    fd = bus_socket_fd(bus)
    if fd is None:
        return None
    with socket.socket(fileno=os.dup(fd)) as sock:  # the same socket; closing the dup only
        if sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF) < wanted_bytes:
            with contextlib.suppress(OSError):  # the kernel refused: keep what it has
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, wanted_bytes)
        granted: int = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        return granted


def meminfo_drops(fd: int) -> int | None:
    """The kernel's count of what it dropped on socket ``fd`` (``SO_MEMINFO``'s
    ``SK_MEMINFO_DROPS``), or None where the kernel does not answer (before Linux 4.12)."""
    with socket.socket(fileno=os.dup(fd)) as sock:  # the same socket; closing the dup only
        try:
            raw = sock.getsockopt(socket.SOL_SOCKET, SO_MEMINFO, _MEMINFO.size)
        except OSError:
            return None
    return _MEMINFO.unpack(raw)[_MEMINFO_DROPS] if len(raw) == _MEMINFO.size else None


class SocketDrops:
    """The kernel's count of frames it dropped on one bus's socket since it was opened
    (receive buffer full): ``meminfo_drops`` on the bus's socket, else found by the socket's
    inode in ``/proc/net/udp{,6}``. Take it while the bus is open (``count()`` is None once the
    socket is closed, or for a socket the kernel counts neither way)."""

    def __init__(self, bus: object, tables: tuple[Path, ...] = UDP_TABLES) -> None:
        fd = bus_socket_fd(bus)
        self.bus = bus
        self.inode = None if fd is None else os.fstat(fd).st_ino
        self.tables = tables
        self.last: int | None = None  # the latest count read (kept after the socket closed)

    def count(self) -> int | None:
        """Frames dropped so far, or None when unknown (also remembered in ``last``)."""
        if self.inode is None:
            return None
        fd = bus_socket_fd(self.bus)
        if fd is not None and os.fstat(fd).st_ino == self.inode:  # still the bus's own socket
            drops = meminfo_drops(fd)
            if drops is not None:
                self.last = drops
                return drops
        return self._table_count()

    def _table_count(self) -> int | None:
        """The count in ``/proc/net/udp{,6}`` (UDP sockets only), or None."""
        wanted = str(self.inode)
        for table in self.tables:
            try:
                lines = table.read_text().splitlines()[1:]
            except OSError:
                continue
            for line in lines:
                fields = line.split()
                if len(fields) > _DROPS_COLUMN and fields[_INODE_COLUMN] == wanted:
                    self.last = int(fields[_DROPS_COLUMN])
                    return self.last
        return None
