"""The C firmware on the board: ``firmware/c`` as a shared library, driven through ctypes.

``CFirmwareBoard`` is a ``FirmwareBoard`` whose ECU is the C port (``firmware/c/ecu.c``) behind
the ABI of ``firmware/c/odocan_fw.h`` instead of ``firmware.ecu.OdomEcu``: the board still does
every bus I/O (acceptance filter, receive ISR, bus-off, transmit), so the rig and the real-time
node do not care which firmware they run. ``make_board(kind, ...)`` / ``board_maker(kind)`` pick
one by name (``--firmware {python,c}``).

The library is built on demand with ``make -C firmware/c lib`` into
``firmware/c/build/libodocan_fw.so`` (make rebuilds it when a source changed, and does nothing
otherwise), or taken from ``$ODOCAN_FW_LIB``: a team's own firmware built against the same ABI.
A missing compiler, make or library is one ``FirmwareBuildError`` naming what is missing.

SecOC (ABI 2, docs/secoc.md): a board with a key provisions it with
``odocan_fw_provision_secoc`` right after ``odocan_fw_init``, with the board's EPOCH cell
(``NvmCell``, or a file: ``sim.board.FileNvm``) behind two C callbacks. A library of ABI 1 (a
team's firmware built before) still runs without a key; asked for one, it is refused in one line.

ABI 3: ``odocan_fw_init`` takes seven parameters, the robot's ``max_wheel_speed_mm_s`` last. A
library of ABI 1 or 2 reads six and bounds steps at its build-time 4 m/s: it runs a robot whose
profile says 4 m/s and is refused, in one line, any other.
"""

from __future__ import annotations

import ctypes
import fcntl
import os
import shutil
import subprocess
from collections.abc import Callable
from importlib import resources
from pathlib import Path
from typing import Protocol, TypeVar

import can

from odocan.firmware.config import MAX_WHEEL_SPEED_DEFAULT_MM_S, RobotParams
from odocan.firmware.errors import ErrorFlag, ErrorMask, State
from odocan.firmware.hal import TICK_PERIOD_US, CanTx, FreshnessNvm
from odocan.sim.board import FirmwareBoard, NvmCell
from odocan.sim.clock import Clock
from odocan.sim.exceptions import ConfigurationError, OdocanError

FIRMWARES = ("python", "c")
ABI_VERSION = 3  # ODOCAN_FW_ABI_VERSION of firmware/c/odocan_fw.h
# what this board speaks: 1 without SecOC, 2 with odocan_fw_provision_secoc, 3 with the speed bound
ABI_VERSIONS = (1, 2, 3)
SECOC_ABI = 2
SPEED_ABI = 3  # odocan_fw_init's seventh parameter, max_wheel_speed_mm_s
# from the package, not ``__file__``: a copy of this module loaded from elsewhere (compiled by
# ``host.accel``, in its cache) still finds the sources
FIRMWARE_C_DIR = Path(str(resources.files("odocan").joinpath("firmware", "c"))).resolve()


def _build_dir() -> Path:
    """``firmware/c/build`` in a checkout; in an installed package that cannot be written (a
    system site-packages), the user's cache (``$XDG_CACHE_HOME/odocan/firmware-c``)."""
    if os.access(FIRMWARE_C_DIR, os.W_OK):
        return FIRMWARE_C_DIR / "build"
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return cache / "odocan" / "firmware-c"


LIBRARY_PATH = _build_dir() / "libodocan_fw.so"
LIBRARY_ENV = "ODOCAN_FW_LIB"  # a prebuilt library with the same ABI (e.g. a team's own)

_Payload = ctypes.c_char * 8  # a frame's ``const uint8_t data[8]``
# ``data`` as a pointer to 8 chars: ``data.contents.raw`` copies them in one step (about 1 us a
# frame less than ``ctypes.string_at`` on a ``uint8_t *``, which is a foreign call of its own).
_TxFn = ctypes.CFUNCTYPE(ctypes.c_bool, ctypes.c_void_p, ctypes.c_uint32, ctypes.POINTER(_Payload))
_NvmRead = ctypes.CFUNCTYPE(ctypes.c_uint32, ctypes.c_void_p)
_NvmWrite = ctypes.CFUNCTYPE(ctypes.c_bool, ctypes.c_void_p, ctypes.c_uint32)
# A ``uint32_t`` argument given as a Python int is a new ``c_uint32`` made by ``from_param`` at
# every foreign call (~1 k instructions; the receive ISR passes two a frame); given as an
# instance of its type it is taken as it is: the identifiers' and lengths' instances, made once
# each (11-bit identifiers and lengths: a bounded set), the same value passed.
_U32_ARGS: dict[int, ctypes.c_uint32] = {}
_U32_ARGS_MAX = 4096
_loaded: dict[Path, ctypes.CDLL] = {}
_T = TypeVar("_T")


class FirmwareBuildError(OdocanError):
    """The C firmware library could not be built or loaded (missing compiler, make, ABI)."""


def _build_library() -> Path:
    """``make -C firmware/c lib`` under a lock (parallel test processes build once); the path."""
    if not (FIRMWARE_C_DIR / "Makefile").is_file():
        raise FirmwareBuildError(f"--firmware c: no C firmware sources at {FIRMWARE_C_DIR}")
    make = shutil.which("make")
    if make is None:
        raise FirmwareBuildError("--firmware c: make not found on PATH (install make)")
    try:
        LIBRARY_PATH.parent.mkdir(parents=True, exist_ok=True)
        lock = open(LIBRARY_PATH.parent / ".lib.lock", "w")  # noqa: SIM115 (closed below)
    except OSError as exc:
        raise FirmwareBuildError(
            f"--firmware c: cannot build in {LIBRARY_PATH.parent}: {exc.strerror}"
        ) from exc
    with lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        command = [make, "-s", "-C", str(FIRMWARE_C_DIR), f"BUILD={LIBRARY_PATH.parent}", "lib"]
        if subprocess.run([*command, "-q"], capture_output=True, check=False).returncode == 0:
            return LIBRARY_PATH  # up to date: no compiler needed
        compiler = os.environ.get("CC", "cc")
        if shutil.which(compiler) is None:
            raise FirmwareBuildError(
                f"--firmware c: C compiler {compiler!r} not found on PATH to build "
                f"{LIBRARY_PATH} (install gcc, or set CC)"
            )
        done = subprocess.run(command, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["(no output)"])[-1]
        raise FirmwareBuildError(f"--firmware c: building {LIBRARY_PATH} failed: {last}")
    return LIBRARY_PATH


def load_library() -> ctypes.CDLL:
    """The firmware library (``$ODOCAN_FW_LIB``, else ours built on demand), its ABI checked."""
    override = os.environ.get(LIBRARY_ENV)
    path = Path(override) if override else _build_library()
    lib = _loaded.get(path)
    if lib is not None:
        return lib
    try:
        lib = ctypes.CDLL(str(path))
    except OSError as exc:
        raise FirmwareBuildError(f"--firmware c: cannot load {path}: {exc}") from exc
    try:
        _declare(lib)
    except AttributeError as exc:
        raise FirmwareBuildError(f"--firmware c: {path} lacks the odocan_fw ABI: {exc}") from exc
    version = lib.odocan_fw_abi_version()
    if version not in ABI_VERSIONS:
        raise FirmwareBuildError(
            f"--firmware c: {path} has ABI version {version}, this board speaks "
            f"{' or '.join(map(str, ABI_VERSIONS))}"
        )
    if version >= SECOC_ABI:
        _declare_secoc(lib)
    _loaded[path] = lib
    return lib


def check_secoc_abi(lib: ctypes.CDLL) -> None:
    """``ConfigurationError`` (one line) unless ``lib`` can be provisioned with a SecOC key."""
    version = lib.odocan_fw_abi_version()
    if version < SECOC_ABI:
        raise ConfigurationError(
            f"--secoc-key: the C firmware {lib._name} has ABI version {version}, which takes no "
            f"SecOC key (odocan_fw_provision_secoc is ABI {SECOC_ABI}): rebuild it"
        )


def check_speed_abi(lib: ctypes.CDLL, params: RobotParams) -> None:
    """``ConfigurationError`` (one line) when ``lib`` predates ABI 3 (its bound is a build-time 4
    m/s) and the robot states another maximum wheel speed."""
    version = lib.odocan_fw_abi_version()
    if version < SPEED_ABI and params.max_wheel_speed_mm_s != MAX_WHEEL_SPEED_DEFAULT_MM_S:
        raise ConfigurationError(
            f"the C firmware {lib._name} has ABI version {version}, bounded at "
            f"{MAX_WHEEL_SPEED_DEFAULT_MM_S} mm/s; the robot's max_wheel_speed is "
            f"{params.max_wheel_speed_mm_s} mm/s (ABI {SPEED_ABI}): rebuild it"
        )


def _declare_secoc(lib: ctypes.CDLL) -> None:
    """ABI 2's odocan_fw_provision_secoc (missing from the library: FirmwareBuildError)."""
    try:
        provision = lib.odocan_fw_provision_secoc
    except AttributeError as exc:
        raise FirmwareBuildError(f"--firmware c: {lib._name} says ABI 2 but lacks {exc}") from exc
    provision.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_uint32, _NvmRead, _NvmWrite,
                          ctypes.c_void_p]
    provision.restype = ctypes.c_int


def _declare(lib: ctypes.CDLL) -> None:
    """The argument and result types of odocan_fw.h."""
    vp, u32 = ctypes.c_void_p, ctypes.c_uint32
    lib.odocan_fw_abi_version.argtypes = []
    lib.odocan_fw_abi_version.restype = u32
    lib.odocan_fw_state_size.argtypes = []
    lib.odocan_fw_state_size.restype = ctypes.c_size_t
    lib.odocan_fw_init.argtypes = [vp, ctypes.c_size_t, ctypes.POINTER(u32), _TxFn, vp]
    lib.odocan_fw_init.restype = ctypes.c_int
    lib.odocan_fw_rx_isr.argtypes = [vp, u32, u32, ctypes.c_char_p]
    lib.odocan_fw_rx_isr.restype = None
    lib.odocan_fw_bus_state.argtypes = [vp, ctypes.c_bool]
    lib.odocan_fw_bus_state.restype = None
    lib.odocan_fw_rx_overrun.argtypes = [vp]
    lib.odocan_fw_rx_overrun.restype = None
    lib.odocan_fw_tick.argtypes = [vp, ctypes.c_uint64]
    lib.odocan_fw_tick.restype = None
    for name in ("odocan_fw_state", "odocan_fw_errors", "odocan_fw_ticks"):
        getattr(lib, name).argtypes = [vp]
        getattr(lib, name).restype = u32


def _u32_arg(value: int) -> ctypes.c_uint32 | int:
    """``value`` as a ``uint32_t`` argument of a foreign call: its cached ``c_uint32`` (made
    once, the value masked to 32 bits as ``from_param`` masks an int), else the int itself."""
    arg = _U32_ARGS.get(value)
    if arg is None:
        if len(_U32_ARGS) >= _U32_ARGS_MAX:
            return value
        arg = _U32_ARGS[value] = ctypes.c_uint32(value)
    return arg


class CEcu:
    """The C ECU with ``OdomEcu``'s entry points (``isr_can_rx``, ``isr_bus_state``, ``tick``)
    and read-only ``state``, ``errors``, ``ticks``; its frames go to ``hal.transmit``."""

    def __init__(
        self,
        hal: CanTx,
        params: RobotParams,
        clock: Clock | None = None,
        *,
        secoc_key: bytes | None = None,
        nvm: FreshnessNvm | None = None,
    ) -> None:
        """``clock``: what ``tick`` passes as ``now_us`` (None: the tick count x 10 ms);
        ``secoc_key`` and ``nvm``: as ``OdomEcu``'s (None: no SecOC; a key without a cell fails
        closed), provisioned through ABI 2."""
        self._lib = lib = load_library()
        if secoc_key is not None:
            check_secoc_abi(lib)
        check_speed_abi(lib, params)
        size = lib.odocan_fw_state_size()
        self._mem = ctypes.create_string_buffer(size)  # malloc'ed: aligned for uint64_t
        self._fw = ctypes.cast(self._mem, ctypes.c_void_p)
        self._hal = hal
        self._clock = clock
        self._pending: BaseException | None = None
        self._tx = _TxFn(self._transmit)  # kept alive as long as the firmware holds it
        raw = (ctypes.c_uint32 * 7)(
            params.counts_per_rev,
            params.wheel_radius_left_nm,
            params.wheel_radius_right_nm,
            params.wheelbase_nm,
            params.counter_bits,
            params.integrator,
            params.max_wheel_speed_mm_s,  # ABI 3 (an older library reads the first six)
        )
        if lib.odocan_fw_init(self._fw, size, raw, self._tx, None) != 0:
            raise FirmwareBuildError("--firmware c: odocan_fw_init refused its state buffer")
        if secoc_key is not None:
            self._provision(secoc_key, nvm)
        self.params = params
        self._isr = lib.odocan_fw_rx_isr
        self._tick = lib.odocan_fw_tick
        self._now_us = ctypes.c_uint64()  # ``tick``'s argument, set, not made, at every tick

    def _provision(self, key: bytes, nvm: FreshnessNvm | None) -> None:
        """odocan_fw_provision_secoc with ``key`` and ``nvm`` behind two C callbacks (kept alive
        with the instance; an exception in one is raised here, like ``_transmit``'s)."""
        if nvm is None:
            read, write = _NvmRead(), _NvmWrite()  # NULL: the firmware fails closed
        else:
            read = _NvmRead(lambda _ctx: self._nvm_call(nvm.read_epoch, 0))
            write = _NvmWrite(lambda _ctx, epoch: self._nvm_call(lambda: nvm.write_epoch(epoch),
                                                                 False))
        self._nvm_fns = (read, write)
        done = self._lib.odocan_fw_provision_secoc(self._fw, key, len(key), read, write, None)
        self._raise_pending()
        if done != 0:
            raise FirmwareBuildError("--firmware c: odocan_fw_provision_secoc refused the key")

    def _nvm_call(self, call: Callable[[], _T], failed: _T) -> _T:
        """An NVM callback's work; an exception cannot cross the C frames: kept, ``failed``."""
        try:
            return call()
        except BaseException as exc:  # re-raised by the caller of the C function
            self._pending = self._pending or exc
            return failed

    def _raise_pending(self) -> None:
        """Raise the exception a callback kept during the last C call, if any."""
        if self._pending is not None:
            pending, self._pending = self._pending, None
            raise pending

    def _transmit(
        self, _ctx: int | None, can_id: int, data: ctypes._Pointer[ctypes.Array[ctypes.c_char]]
    ) -> bool:
        """The firmware's ``can_tx_fn``: one frame to the HAL. An exception cannot cross the C
        frames: it is kept, the frame counts as refused, and ``tick`` raises it on return."""
        try:
            return self._hal.transmit(can_id, data.contents.raw)
        except BaseException as exc:  # re-raised by tick()
            self._pending = self._pending or exc
            return False

    def isr_can_rx(self, can_id: int, data: bytes) -> None:
        """CAN receive interrupt: the frame into the C mailbox (the cached arguments looked up
        here: no Python call of ``_u32_arg`` a frame once they are made)."""
        get = _U32_ARGS.get
        id_arg: ctypes.c_uint32 | int | None = get(can_id)
        len_arg: ctypes.c_uint32 | int | None = get(len(data))
        if id_arg is None or len_arg is None:
            id_arg, len_arg = _u32_arg(can_id), _u32_arg(len(data))
        self._isr(self._fw, id_arg, len_arg, data)

    def isr_bus_state(self, bus_off: bool) -> None:
        """CAN controller status interrupt: bus-off entered (True) or left (False)."""
        self._lib.odocan_fw_bus_state(self._fw, bus_off)

    def isr_rx_overrun(self) -> None:
        """CAN controller overrun interrupt: its receive FIFO dropped frames."""
        self._lib.odocan_fw_rx_overrun(self._fw)

    def tick(self, now_us: int | None = None) -> None:
        """One period of the C main loop. ``now_us``: the board's time, when the board passes
        it; else the clock's, else the tick count x 10 ms (the firmware's time, as in Python)."""
        if now_us is None:
            now_us = (
                round(self._clock.now_s() * 1e6)
                if self._clock is not None
                else self.ticks * TICK_PERIOD_US
            )
        arg = self._now_us
        arg.value = now_us  # masked to 64 bits as ``from_param`` would
        self._tick(self._fw, arg)
        self._raise_pending()

    @property
    def state(self) -> State:
        """The firmware state (ODOM_STATUS STATE)."""
        return State(self._lib.odocan_fw_state(self._fw))

    @property
    def errors(self) -> ErrorMask:
        """A snapshot of the sticky error mask."""
        mask = ErrorMask()
        mask.set(ErrorFlag(self._lib.odocan_fw_errors(self._fw)))
        return mask

    @property
    def ticks(self) -> int:
        """The u32 tick count."""
        return int(self._lib.odocan_fw_ticks(self._fw))


class CFirmwareBoard(FirmwareBoard):
    """``FirmwareBoard`` with the C firmware as its ECU: same bus I/O, same interface."""

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
        lib = load_library()  # built and loaded (and its ABI checked) before the board starts
        if secoc_key is not None:
            check_secoc_abi(lib)
        super().__init__(bus, params, clock, accept_ids, secoc_key=secoc_key, nvm=nvm)

    def _start_firmware(self) -> CEcu:  # type: ignore[override]
        """Reset: a C firmware with the board's configuration (key and NVM cell)."""
        return CEcu(self, self.params, self.clock, secoc_key=self.secoc_key, nvm=self.nvm)


class BoardMaker(Protocol):
    """A board class: ``(bus, params, clock, accept_ids, *, secoc_key=None, nvm=None)``."""

    def __call__(
        self,
        bus: can.BusABC,
        params: RobotParams,
        clock: Clock,
        accept_ids: frozenset[int] | None = None,
        *,
        secoc_key: bytes | None = None,
        nvm: NvmCell | None = None,
    ) -> FirmwareBoard: ...


def board_maker(
    kind: str, *, secoc: bool = False, params: RobotParams | None = None
) -> BoardMaker:
    """The board class of firmware ``kind`` ("python" or "c"), the C library built and loaded
    now: call it before opening a bus or a log, so a refusal leaves nothing to close or to
    truncate (``secoc``: a SecOC key will be provisioned: a C library of ABI 1 is refused;
    ``params``: the robot it will run: a library older than ABI 3 is refused unless the robot's
    speed bound is its built-in 4 m/s)."""
    if kind == "python":
        return FirmwareBoard
    if kind == "c":
        lib = load_library()
        if secoc:
            check_secoc_abi(lib)
        if params is not None:
            check_speed_abi(lib, params)
        return CFirmwareBoard
    raise ConfigurationError(f"unknown firmware {kind!r} (known: {', '.join(FIRMWARES)})")


def make_board(
    kind: str,
    bus: can.BusABC,
    params: RobotParams,
    clock: Clock,
    accept_ids: frozenset[int] | None = None,
) -> FirmwareBoard:
    """A board running firmware ``kind`` ("python": ``firmware/``, "c": ``firmware/c``)."""
    return board_maker(kind)(bus, params, clock, accept_ids)
