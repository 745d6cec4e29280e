"""The C firmware (``firmware/c``) in the rig: the same bytes on the bus as the Python firmware.

``odocan run --log`` twice, ``--firmware python`` and ``--firmware c``, must write the SAME
candump file, byte for byte: both shipped robots, every integrator, with and without ``--faults``
(20 simulated s each, 4 minutes of driving in all), plus a closed-loop navigation session where
the firmware drives the motors itself (NAV_GOAL, ODOM_SET_POSE, ODOM_CONFIG). Any change to
``firmware/ecu.py`` that is not carried into ``firmware/c/ecu.c`` (or the other way round) fails
here: ``pytest tests/test_c_rig.py``. Then the README's example pytest passes against the C
firmware, in lockstep and as a separate ``odocan firmware --firmware c`` process on udp_multicast.

Skips with the reason when make or a C compiler is missing, and fails instead under CI=true.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import math
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import can
import pytest

from odocan.firmware import frames as fr
from odocan.firmware.config import RobotParams
from odocan.firmware.errors import State
from odocan.host.cli.app import main
from odocan.host.testkit import plugin
from odocan.host.testkit.backends import LockstepBackend, parse_bus_spec
from odocan.host.testkit.options import RigOptions
from odocan.host.testkit.rig import make_rig
from odocan.sim import cboard
from odocan.sim.board import FirmwareBoard
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.rig import INTEGRATORS
from tests import test_pytest_plugin
from tests.requires import require_executables
from tests.test_pytest_plugin import plugin_args

pytest_plugins = ["pytester"]
udp_bus = test_pytest_plugin.udp_bus  # the fixture: a fresh loopback udp_multicast channel

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "test_my_robot.py"
# a configuration the host accepts (the firmware judges it): pmir-like, 32-bit counters, rk2
PMIR_CONFIG = {
    "counts_per_rev": 4096,
    "wheel_radius_left_m": 0.08,
    "wheel_radius_right_m": 0.08,
    "wheelbase_m": 0.3,
    "counter_bits": 32,
    "integrator": "rk2",
}
DURATION_S = 20  # simulated seconds per compared run
# every kind of fault on what MOTOR_CTRL and SIM send (and, seeded apart, on what ODOM_MCU sends):
# loss, bursts, duplicates, delays, bit flips, babbling and a bus-off the firmware must notice
FAULTS = "drop=0.05,burst=0.01:3,dup=0.02,delay=0.02:5,flip=0.02,babble=100,busoff=5:1,seed=3"


@pytest.fixture(scope="module", autouse=True)
def c_library() -> None:
    """The C firmware library, built once (skip, or fail under CI, without make and cc)."""
    require_executables("make", "cc", install="apt-get install gcc make")
    cboard.load_library()


def _run_log(tmp_path: Path, firmware: str, *args: str) -> bytes:
    """``odocan run ... --log`` with ``firmware``; the candump file's bytes."""
    log = tmp_path / f"{firmware}.log"
    argv = ["run", "--duration", str(DURATION_S), "--log", str(log), "--firmware", firmware]
    assert main([*argv, *args]) in (0, 1)  # 1: a verdict FAIL under faults, still a full log
    return log.read_bytes()


@pytest.mark.parametrize("faults", ["", FAULTS], ids=["clean", "faults"])
@pytest.mark.parametrize("integrator", INTEGRATORS)
@pytest.mark.parametrize("robot", ["pmir", "kobuki"])
def test_c_firmware_log_is_byte_identical(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], robot: str, integrator: str, faults: str
) -> None:
    args = ["--robot", robot, "--integrator", integrator, "--seed", "7"]
    if faults:
        args += ["--faults", faults]
    python_log = _run_log(tmp_path, "python", *args)
    c_log = _run_log(tmp_path, "c", *args)
    out = capsys.readouterr().out
    assert "c firmware" in out  # the run says which firmware it judged
    pose_x = f" {fr.ODOM_POSE_X_ID:03X}#".encode()
    odom_frames = sum(1 for line in python_log.splitlines() if pose_x in line)
    assert odom_frames >= DURATION_S * 40  # ODOM_POSE_X every 20 ms: the firmware spoke
    if python_log != c_log:
        first = next(
            i
            for i, (a, b) in enumerate(
                zip(python_log.splitlines(), c_log.splitlines(), strict=False)
            )
            if a != b
        )
        pytest.fail(
            f"C and Python firmware logs differ first at line {first + 1}: "
            f"{python_log.splitlines()[first]!r} vs {c_log.splitlines()[first]!r}"
        )


class _Lines(can.Listener):
    """Every frame the host hears, as (timestamp, id, data)."""

    def __init__(self) -> None:
        self.frames: list[tuple[float, int, bytes]] = []

    def on_message_received(self, msg: can.Message) -> None:
        self.frames.append((msg.timestamp, msg.arbitration_id, bytes(msg.data)))


def _closed_loop(firmware: str) -> tuple[list[tuple[float, int, bytes]], State]:
    """A navigation session (path of goals, a pose overwrite, a refused and an accepted
    configuration) with ``firmware`` driving the motors; every frame and the final state."""
    rig = make_rig(RigOptions(errors="ed=1.002", seed=5, integrator="rk2", firmware=firmware))
    lines = _Lines()
    try:
        backend = rig.backend
        assert isinstance(backend, LockstepBackend)
        backend.rig.listeners.append(lines)
        rig.path([(0.5, 0.0), (0.5, 0.5, math.pi / 2), (0.0, 0.5)])
        rig.run_until_reached(timeout_s=60)
        rig.set_pose(1.0, -1.0, 0.5)
        absurd = {**PMIR_CONFIG, "counts_per_rev": 1, "wheelbase_m": 0.02}  # 1 count: 1/4 turn
        with pytest.raises(AssertionError, match="NACK"):
            rig.command("config", absurd)
        rig.command("config", {**PMIR_CONFIG, "wheel_radius_left_m": 0.0801})
        rig.goto(1.5, -1.0, mode="go_to_goal")
        rig.step(20.0)  # go-to-goal under the new wheel radius (reached or not: same bytes)
        return lines.frames, backend.rig.board.ecu.state
    finally:
        rig.close()


def test_c_firmware_navigates_byte_identically() -> None:
    python_frames, python_state = _closed_loop("python")
    c_frames, c_state = _closed_loop("c")
    assert c_state is python_state is State.OK
    assert len(python_frames) > 3000
    assert c_frames == python_frames


# --- the board and the library ------------------------------------------------------------------


def test_make_board_names_the_firmwares() -> None:
    assert cboard.board_maker("python") is FirmwareBoard
    assert cboard.board_maker("c") is cboard.CFirmwareBoard
    with pytest.raises(ConfigurationError, match="unknown firmware 'rust'"):
        cboard.board_maker("rust")
    assert plugin._FIRMWARES == cboard.FIRMWARES  # the plugin's copy (it loads no sim module)


def test_library_speaks_the_abi_version() -> None:
    lib = cboard.load_library()
    assert lib.odocan_fw_abi_version() == cboard.ABI_VERSION
    buffer = ctypes.create_string_buffer(8)
    params = (ctypes.c_uint32 * 6)(4096, 80_000_000, 80_000_000, 300_000_000, 32, 2)
    tx = cboard._TxFn(lambda _ctx, _id, _data: True)
    assert lib.odocan_fw_init(ctypes.cast(buffer, ctypes.c_void_p), 8, params, tx, None) == -1


def test_invalid_params_start_the_c_firmware_in_fault() -> None:
    sent: list[tuple[int, bytes]] = []

    class Hal:
        def transmit(self, can_id: int, data: bytes) -> bool:
            sent.append((can_id, data))
            return True

    params = RobotParams(0, 80_000_000, 80_000_000, 300_000_000, 32, 2)
    ecu = cboard.CEcu(Hal(), params)
    for _ in range(10):
        ecu.tick()
    assert ecu.state is State.FAULT
    assert ecu.ticks == 10
    assert ecu.errors.bits & 2  # CONFIG_INVALID
    assert any(can_id == fr.ODOM_STATUS_ID for can_id, _ in sent)  # ODOM_STATUS still goes out


def test_a_transmit_exception_reaches_the_caller_after_the_tick() -> None:
    class Broken:
        def transmit(self, can_id: int, data: bytes) -> bool:
            raise RuntimeError(f"driver gone ({can_id:#x})")

    params = RobotParams(4096, 80_000_000, 80_000_000, 300_000_000, 32, 2)
    ecu = cboard.CEcu(Broken(), params)

    def ten_ticks() -> None:
        for _ in range(10):
            ecu.tick()

    with pytest.raises(RuntimeError, match="driver gone"):
        ten_ticks()
    assert 1 <= ecu.ticks <= 10  # the tick ran to its end, then the error was raised


def test_another_library_runs_through_odocan_fw_lib(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """A team's library in $ODOCAN_FW_LIB (here a copy of ours) is the firmware that runs."""
    theirs = tmp_path / "libtheirs.so"
    shutil.copyfile(cboard.load_library()._name, theirs)
    python_log = _run_log(tmp_path, "python")
    monkeypatch.setenv(cboard.LIBRARY_ENV, str(theirs))
    assert _run_log(tmp_path, "c") == python_log
    assert theirs in cboard._loaded
    capsys.readouterr()


def test_a_missing_library_is_one_error_line(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    missing = tmp_path / "libnothere.so"
    monkeypatch.setenv(cboard.LIBRARY_ENV, str(missing))
    assert main(["run", "--duration", "1", "--firmware", "c"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: --firmware c: cannot load {missing}")
    assert err.count("\n") == 1


def test_a_library_without_the_abi_is_one_error_line(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    libc = ctypes.util.find_library("c")
    assert libc is not None
    monkeypatch.setenv(cboard.LIBRARY_ENV, libc)
    assert main(["run", "--duration", "1", "--firmware", "c"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: --firmware c: {libc} lacks the odocan_fw ABI: ")
    assert err.count("\n") == 1


def test_an_unwritable_build_directory_is_one_error_line(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    blocker = tmp_path / "a-file"
    blocker.write_text("not a directory")
    monkeypatch.setattr(cboard, "LIBRARY_PATH", blocker / "build" / "libodocan_fw.so")
    assert main(["run", "--duration", "1", "--firmware", "c"]) == 2
    err = capsys.readouterr().err
    assert err == f"error: --firmware c: cannot build in {blocker / 'build'}: Not a directory\n"


def test_a_missing_compiler_is_one_error_line(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    sources = tmp_path / "c"  # a fresh copy of firmware/c: its library is not built yet
    shutil.copytree(cboard.FIRMWARE_C_DIR, sources, ignore=shutil.ignore_patterns("build"))
    library = sources / "build" / "libodocan_fw.so"
    monkeypatch.setattr(cboard, "FIRMWARE_C_DIR", sources)
    monkeypatch.setattr(cboard, "LIBRARY_PATH", library)
    monkeypatch.setenv("CC", "no-such-cc")
    assert main(["firmware", "--duration", "1", "--firmware", "c", "-i", "virtual"]) == 2
    err = capsys.readouterr().err
    assert err == (
        f"error: --firmware c: C compiler 'no-such-cc' not found on PATH to build {library} "
        "(install gcc, or set CC)\n"
    )
    assert not library.exists()


# --- the README's example against the C firmware --------------------------------------------------


def _plugin_run(pytester: pytest.Pytester, *args: str) -> pytest.RunResult:
    return pytester.runpytest(*plugin_args(), "-p", "no:cacheprovider", *args)


def test_the_readme_example_passes_on_the_c_firmware_in_lockstep(
    pytester: pytest.Pytester,
) -> None:
    pytester.makepyfile(test_users_robot=EXAMPLE.read_text())
    result = _plugin_run(pytester, "--odocan-firmware", "c")
    result.assert_outcomes(passed=2)
    result.stdout.fnmatch_lines(["odocan: our C firmware (firmware/c) in lockstep*"])


def test_the_firmware_option_needs_lockstep(pytester: pytest.Pytester) -> None:
    pytester.makepyfile(test_any="def test_rig(odocan_rig):\n    odocan_rig()\n")
    bus = "interface=udp_multicast,channel=239.255.1.1,hop_limit=0"
    result = _plugin_run(pytester, "--odocan-firmware", "c", "--odocan-bus", bus)
    result.stdout.fnmatch_lines(["*--odocan-firmware chooses our firmware in lockstep*"])
    assert result.ret != 0


def test_the_readme_example_passes_against_a_c_firmware_process(
    pytester: pytest.Pytester, udp_bus: str
) -> None:
    kwargs = parse_bus_spec(udp_bus)
    argv = [sys.executable, "-m", "odocan", "firmware", "--firmware", "c",
            "-i", "udp_multicast", "-c", kwargs["channel"],
            "--bus-arg", f"port={kwargs['port']}", "--bus-arg", "hop_limit=0"]  # fmt: skip
    firmware = subprocess.Popen(argv, cwd=ROOT, stderr=subprocess.PIPE, text=True)
    try:
        pytester.makepyfile(test_users_robot=EXAMPLE.read_text())
        result = _plugin_run(pytester, "--odocan-bus", udp_bus, *test_pytest_plugin.ACK_TIMEOUT)
    finally:
        firmware.send_signal(signal.SIGTERM)
        try:
            err = firmware.communicate(timeout=10)[1]
        except subprocess.TimeoutExpired:
            firmware.kill()
            err = firmware.communicate()[1]
    result.assert_outcomes(passed=2)
    result.stdout.fnmatch_lines([f"odocan: external firmware on {udp_bus} (real time)"])
    assert err.startswith("odocan firmware: c firmware, ")
    assert "Traceback" not in err
