"""The firmware's board: its HAL implemented on a python-can bus and a clock.

The bus plays the MCU's CAN controller (11-bit data frames only: error, remote and extended frames
never reach the firmware's mailbox, as a hardware acceptance filter would drop them, nor frames
outside ``accept_ids`` when it is given); the caller's
periodic loop plays its timer and calls ``run_tick`` every ``TICK_PERIOD_US``; the clock plays the
MCU's free-running microsecond timer, passed to every tick.

A stalled MCU (a debugger halt, a SIGSTOPped process, a tick loop that fell behind) runs no receive
ISR: while it is halted its CAN controller keeps the first ``HW_RX_FIFO_FRAMES`` frames in its
receive FIFO (FIFO-locked mode, as bxCAN) and overruns the rest. So when ``run_tick`` comes
``HALT_AFTER_S`` or more after the previous one (as long as the firmware calls lost time), only that
many waiting frames reach the firmware; the others are dropped and the overrun interrupt tells the
firmware, as would the hardware.

SecOC (docs/secoc.md): a board built with ``secoc_key`` provisions the firmware with it and
with its ``NvmCell``, the EPOCH cell of data flash: ``reboot`` starts a new firmware on the same
cell, so the freshness values of the previous boot stay closed. ``FileNvm`` is the same cell in
a file (``odocan firmware --nvm PATH``): a firmware process restarted on it is a reboot.
"""

from __future__ import annotations

import contextlib
import os
import stat
import struct
import zlib
from collections.abc import Iterable
from pathlib import Path

import can

from odocan.firmware.config import RobotParams
from odocan.firmware.ecu import LOST_TIME_PERIODS, OdomEcu
from odocan.firmware.hal import TICK_PERIOD_US
from odocan.sim.clock import Clock, LockstepClock
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.framebatch import Received
from odocan.sim.mcu import HW_RX_FIFO_FRAMES as HW_RX_FIFO_FRAMES
from odocan.sim.node import BusNode
from odocan.sim.transport import OdocanBus

TICK_S = TICK_PERIOD_US / 1e6
TX_LATENCY_S = 0.001  # the firmware's frames leave 1 ms after the tick that made them
# A tick this long after the previous one: the MCU was halted (the firmware's TIME_LOST). A
# merely late tick is not: a real MCU's receive interrupt would have run meanwhile.
HALT_AFTER_S = (LOST_TIME_PERIODS - 0.5) * TICK_S
JOIN_DRAIN_FRAMES = 1 << 16  # frames dropped at the join at most: a flood cannot hold it
_U32 = 0xFFFF_FFFF


class NvmCell:
    """One u32 cell of non-volatile memory (``firmware.hal.FreshnessNvm``): survives ``reboot``.

    ``fail_writes`` plays a worn or locked flash page (the firmware then fails closed)."""

    def __init__(self, epoch: int = 0) -> None:
        self.epoch = epoch & _U32
        self.writes = 0
        self.fail_writes = False

    def read_epoch(self) -> int:
        """The stored EPOCH (0: never written, an erased cell)."""
        return self.epoch

    def write_epoch(self, epoch: int) -> bool:
        """Store ``epoch``; False when the page refuses writes."""
        if self.fail_writes:
            return False
        self.epoch = epoch & _U32
        self.writes += 1
        return True


NVM_MAGIC = b"ODNV"  # the file's first 4 bytes: an odocan NVM image, layout version 1
NVM_LAYOUT = struct.Struct("<4sII")  # magic, EPOCH (u32), CRC-32 (zlib) of magic + EPOCH


class FileNvm(NvmCell):
    """The EPOCH cell in a file: 12 bytes, ``ODNV`` + EPOCH (u32 LE) + CRC-32 of the first 8.

    A missing file is an erased cell (EPOCH 0), created at the first write. A file of another
    length, magic or CRC (a torn or foreign file) is refused at once (``ConfigurationError``):
    reading it as 0 would reopen every freshness value used before, so the recovery is a person's
    call (docs/secoc.md: delete the file AND provision a new key). Each write goes to a temporary
    file in the same directory, is fsynced, then renamed over the old one (atomic on POSIX): a
    crash leaves the old EPOCH or the new one, never half of one. A write that fails (disk full,
    read-only) returns False, so the firmware fails closed, and keeps the reason in ``error``."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.error: str | None = None
        super().__init__(self._load())

    def _load(self) -> int:
        """The stored EPOCH (0 when the file does not exist); ConfigurationError when corrupt
        or not a regular file (a FIFO would block the read for ever, a device is no NVM)."""
        try:
            mode = self.path.stat().st_mode
            if not stat.S_ISREG(mode):
                raise ConfigurationError(
                    f"NVM file {self.path}: not a regular file ({_file_kind(mode)})"
                )
            raw = self.path.read_bytes()
        except FileNotFoundError:
            return 0
        except OSError as exc:
            raise ConfigurationError(f"NVM file {self.path}: {exc.strerror or exc}") from None
        if len(raw) != NVM_LAYOUT.size:
            raise ConfigurationError(
                f"NVM file {self.path}: {len(raw)} bytes, expected {NVM_LAYOUT.size} (corrupt or "
                "not an odocan NVM file)"
            )
        magic, epoch, crc = NVM_LAYOUT.unpack(raw)
        if magic != NVM_MAGIC or crc != zlib.crc32(raw[:8]):
            raise ConfigurationError(
                f"NVM file {self.path}: bad {'magic' if magic != NVM_MAGIC else 'CRC'} "
                "(corrupt or not an odocan NVM file)"
            )
        return int(epoch)

    def write_epoch(self, epoch: int) -> bool:
        """Store ``epoch`` in the file (temporary file, fsync, rename); False when it failed."""
        if self.fail_writes:
            return False
        head = NVM_MAGIC + struct.pack("<I", epoch & _U32)
        temp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
        try:
            with open(temp, "wb") as out:
                out.write(head + struct.pack("<I", zlib.crc32(head)))
                out.flush()
                os.fsync(out.fileno())
            os.replace(temp, self.path)
            _fsync_dir(self.path.parent)
        except OSError as exc:
            self.error = f"NVM file {self.path}: {exc.strerror or exc}"
            with contextlib.suppress(OSError):
                temp.unlink(missing_ok=True)
            return False
        return super().write_epoch(epoch)


def _file_kind(mode: int) -> str:
    """What a non-regular file is, for an error message."""
    kinds = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a device"),
             (stat.S_ISBLK, "a device"), (stat.S_ISSOCK, "a socket"))
    return next((name for test, name in kinds if test(mode)), "not a file")


def _fsync_dir(directory: Path) -> None:
    """Make a rename in ``directory`` durable (POSIX: fsync the directory)."""
    fd = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class FirmwareBoard(BusNode):
    """An ``OdomEcu`` on a python-can bus: receive ISR from ``recv``, transmit with ``send``."""

    def __init__(
        self,
        bus: can.BusABC,
        params: RobotParams,
        clock: Clock,
        accept_ids: frozenset[int] | None = None,
        *,
        secoc_key: bytes | None = None,
        nvm: NvmCell | None = None,
    ) -> None:
        """``accept_ids``: the acceptance filter's IDs (None: every 11-bit data frame);
        ``secoc_key``: the firmware's SecOC key (None: no SecOC), its EPOCH in ``nvm`` (default:
        a fresh cell)."""
        super().__init__(bus, clock)
        self.accept_ids = accept_ids
        self.params = params
        self.secoc_key = secoc_key
        self.nvm = nvm if nvm is not None else NvmCell()
        self.ecu = self._start_firmware()
        self._bus_off = False
        self.frames_dropped_by_filter = 0
        self.frames_overrun = 0  # frames the halted MCU's receive FIFO could not hold
        self._last_run_s: float | None = None
        # The stamp of the firmware's frames in a lean tick (``run_tick``; None outside one).
        self._lean_stamp_s: float | None = None

    tx_latency_s = TX_LATENCY_S

    def _start_firmware(self) -> OdomEcu:
        """Reset: a firmware with the board's configuration (key and NVM cell)."""
        if self.secoc_key is None:
            return OdomEcu(self, self.params)
        return OdomEcu(self, self.params, secoc_key=self.secoc_key, nvm=self.nvm)

    def join_bus(self) -> int:
        """The CAN controller leaves initialization mode (the MCU's init done, its first tick
        next): the frames the bus carried while it was opened are not received, as a controller
        receives none before it is in normal mode; how many there were. ``odocan firmware``
        joins before its loop: a process that had opened its bus 0.7 s before its first tick (a
        loaded machine) gave its new firmware 79 frames at once (``tests/test_trial38.py``)."""
        dropped = 0
        while dropped < JOIN_DRAIN_FRAMES and self.bus.recv(0) is not None:
            dropped += 1
        return dropped

    def reboot(self) -> None:
        """A reset of the MCU: RAM lost (a new firmware, INIT), the NVM cell kept."""
        self.ecu = self._start_firmware()
        self._last_run_s = None

    def transmit(self, can_id: int, data: bytes) -> bool:
        """The HAL's transmit (``firmware.hal.CanTx``): ``send_frame``; on the lean transport's
        open, instant, simulated-time handle straight onto its wire (``OdocanBus.send_data``'s
        own path, two calls less a frame: the firmware sends ~2 frames a tick)."""
        bus = self.bus
        stamp_s = self._lean_stamp_s  # a lean tick's: the handle's checks done, the time added
        if stamp_s is not None:
            bus._wire.deliver_data(bus, stamp_s, can_id, data)  # type: ignore[attr-defined]
            self.frames_sent += 1
            return True
        if type(bus) is OdocanBus and bus.timing is None and bus._open and bus.preserve_timestamps:
            bus._wire.deliver_data(bus, self.clock.now_s() + self.tx_latency_s, can_id, data)
            self.frames_sent += 1
            return True
        return self.send_frame(can_id, data)

    def service_rx(self, fifo_frames: int | None = None) -> None:
        """Deliver the frames waiting on the bus to the firmware's receive ISR: all of them, or
        (after a halt) the first ``fifo_frames`` that pass the filter, the rest overrun."""
        bus = self.bus
        isr = self.ecu.isr_can_rx
        accept = self.accept_ids
        if type(bus) is OdocanBus and bus.timing is None:
            frames: Iterable[Received] = bus.drain()  # the lean transport: no Message built
            if accept is None and fifo_frames is None:  # the common tick: every frame, no FIFO
                self._deliver_all(frames)
                return
        else:
            frames = iter(lambda: bus.recv(0), None)
        overrun = 0
        for frame in frames:
            if isinstance(frame, tuple):  # a classic 11-bit data frame (``send_data``'s)
                can_id, data = frame[1], frame[2]
            elif frame.is_error_frame or frame.is_remote_frame or frame.is_extended_id:
                self.frames_dropped_by_filter += 1
                continue
            else:
                can_id, data = frame.arbitration_id, bytes(frame.data)
            if accept is not None and can_id not in accept:
                self.frames_dropped_by_filter += 1
            elif fifo_frames is not None and fifo_frames <= 0:
                overrun += 1
            else:
                isr(can_id, data)
                if fifo_frames is not None:
                    fifo_frames -= 1
        if overrun:
            self.frames_overrun += overrun
            self.ecu.isr_rx_overrun()

    def _deliver_all(self, frames: Iterable[Received]) -> None:
        """``service_rx`` with no acceptance filter and no FIFO limit: every classic data frame
        to the receive ISR, the others dropped (counted) as the filter would."""
        isr = self.ecu.isr_can_rx
        for frame in frames:
            if isinstance(frame, tuple):  # a classic 11-bit data frame (``send_data``'s)
                isr(frame[1], frame[2])
            elif frame.is_error_frame or frame.is_remote_frame or frame.is_extended_id:
                self.frames_dropped_by_filter += 1
            else:
                isr(frame.arbitration_id, bytes(frame.data))

    def run_tick(self) -> None:
        """One timer period: the pending interrupts (status, receive), then the firmware's tick
        with the timer's microseconds (the clock's, wrapped to u32)."""
        now_s = self.clock.now_s()
        halted = self._last_run_s is not None and now_s - self._last_run_s >= HALT_AFTER_S
        self._last_run_s = now_s
        bus = self.bus
        if type(bus) is not OdocanBus or self._bus_off:  # the lean handle is never bus-off
            self._service_bus_state()
        elif not halted and self.accept_ids is None and self._take_lean(bus):
            # The firmware's frames straight onto the open, instant handle's wire stamped now
            # plus the latency (``transmit``: the handle's checks and a lockstep clock's time
            # are the same for every frame of the tick, done here once; a wall clock moves
            # during the tick: each frame reads it).
            if bus.preserve_timestamps and type(self.clock) is LockstepClock:
                self._lean_stamp_s = now_s + self.tx_latency_s
            try:
                self.ecu.tick(round(now_s * 1e6) & _U32)
            finally:
                self._lean_stamp_s = None
            return
        self.service_rx(HW_RX_FIFO_FRAMES if halted else None)
        self.ecu.tick(round(now_s * 1e6) & _U32)

    def _take_lean(self, bus: OdocanBus) -> bool:
        """``service_rx()`` of the common tick on the lean transport's open, instant, unfiltered
        handle, from its queue: the frames waiting now, in bus order, to the receive ISR (a
        ``DataFrame`` by its fields, a ``Message`` as ``_deliver_all`` takes it); no list, no
        ``drain`` call (it runs every tick). False, nothing taken: ``service_rx`` does it."""
        if bus.timing is not None or not bus._open or bus._filters is not None:
            return False
        queue = bus._queue
        if queue:
            isr, popleft = self.ecu.isr_can_rx, queue.popleft
            for _ in range(len(queue)):  # those queued now: as ``drain``, whatever comes after
                frame = popleft()
                if type(frame) is tuple:
                    isr(frame[1], frame[2])
                else:
                    self._deliver_all((frame,))
        return True

    def _service_bus_state(self) -> None:
        """The controller's status interrupt: report entering and leaving bus-off."""
        bus = self.bus  # the lean transport's instant handle is never bus-off (BusABC.state)
        bus_off = type(bus) is not OdocanBus and bus.state is can.BusState.ERROR
        if bus_off != self._bus_off:
            self._bus_off = bus_off
            self.ecu.isr_bus_state(bus_off)
