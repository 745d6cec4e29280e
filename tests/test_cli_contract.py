"""The command line's contract for bad input: exit 2, exactly one line ``error: ...``, no traceback.

A table of bad invocations across every subcommand, each run in-process through
``odocan.host.cli.app.main(argv)`` (fast; stderr captured), plus what happens around it: the
summary still printed when an output fails at the very end, ``--debug`` anywhere on the line,
a closed stdout, and ``LockstepRig.close()`` releasing every bus when a listener fails.
MQTT connection failures are not here (host/mqtt's own tests); the bridge and fleet rows fail
in argument validation, before any broker is contacted.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import can
import pytest

from odocan.host.cli.app import SUBCOMMANDS, main

ROOT = Path(__file__).resolve().parents[1]

# (argv with {tmp}, {foreign}, {empty}, {text} placeholders, words the error line must contain)
BAD: list[tuple[str, tuple[str, ...]]] = [
    # run
    ("run --seed -1", ("--seed", "-1")),
    ("run --seed 4294967296", ("--seed", "4294967295")),
    ("run --seed abc", ("--seed", "abc")),
    ("run --duration 0.001", ("--duration", "0.001")),
    ("run --duration 1e12", ("--duration", "1e12")),
    ("run --duration nan", ("--duration", "nan")),
    ("run --duration inf", ("--duration",)),
    ("run --duration 1 --faults drop=1", ("no frame", "--faults drop=1")),
    ("run --duration 1 --faults flip=1", ("no ODOM_POSE_X frame", "--faults flip=1")),
    ("run --faults drop=2", ("drop", "[0, 1]")),
    ("run --faults babble=1e9", ("babble", "20000")),
    ("run --faults delay=0.1:1e9", ("delay", "60000")),
    ("run --faults seed=-3", ("seed",)),
    ("run --faults bogus=1", ("bogus",)),
    ("run --faults busoff=3:0", ("busoff=3:0", "DUR", "> 0")),
    ("run --report /dev/full", ("--report /dev/full", "not a regular file")),
    ("run --report /proc/x/f.json", ("--report /proc/x/f.json", "/proc/x")),
    ("run --report {tmp}", ("--report", "is a directory")),
    ("run --log {tmp}/out.txt", ("--log", "out.txt", ".txt")),
    ("run --log /nonexistent/dir/x.log", ("--log /nonexistent/dir/x.log",)),
    ("run --plot {tmp}/x.gif", ("--plot", ".gif")),
    ("run --integrator midpoint", ("midpoint",)),
    ("run --scenario nope", ("nope",)),
    ("run --robot nosuchbot", ("nosuchbot",)),
    ("run --errors ed=abc", ("ed",)),
    ("run --tolerance -1", ("--tolerance",)),
    ("run --no-such-option", ("--no-such-option",)),
    # analyze
    ("analyze /nonexistent/drive.log", ("/nonexistent/drive.log",)),
    ("analyze {foreign}", ("no WHEEL_ENCODERS frame", "none of them an odocan frame")),
    ("analyze {empty}", ("empty.log", "empty log")),
    ("analyze {corrupt}", ("none of the 200 WHEEL_ENCODERS frames passes its E2E check",
                           "corrupted")),
    ("analyze {text}", ("notes.txt",)),
    ("analyze {foreign} --report /dev/full", ("--report /dev/full",)),
    ("analyze {foreign} --dbc /nonexistent/x.dbc", ("/nonexistent/x.dbc",)),
    ("analyze {foreign} --tolerance pos=0", ("--tolerance",)),
    ("analyze", ("LOG",)),
    ("analyze {foreign} {empty} --report {tmp}/r.json", ("--report takes a single LOG",)),
    ("analyze {foreign} {empty} --report {tmp}/r.json --junit {tmp}/j.xml",
     ("--report, --junit take a single LOG",)),
    # replay
    ("replay /nonexistent/drive.log", ("/nonexistent/drive.log",)),
    ("replay {foreign}", ("no WHEEL_ENCODERS frame",)),
    ("replay {foreign} --realtime -i virtual --speed 0", ("--speed",)),
    ("replay {foreign} --realtime -i virtual --speed 1e9", ("--speed", "1000")),
    ("replay {foreign} --speed 2", ("--speed", "only with --realtime")),
    ("replay {foreign} --realtime -i virtual --report {tmp}/r.json", ("--report",)),
    ("replay {foreign} --log /proc/x/out.log", ("--log /proc/x/out.log",)),
    # monitor
    ("monitor --duration 0", ("--duration",)),
    ("monitor --duration -5", ("--duration", "-5")),
    ("monitor --duration 1e9", ("--duration", "604800")),
    ("monitor -i nosuchinterface --duration 0.1", ("nosuchinterface",)),
    ("monitor --broker http://example.org", ("http://example.org",)),
    ("monitor --broker mqtt://127.0.0.1:1 -i virtual", ("--broker", "-i")),
    ("monitor --dbc /nonexistent/x.dbc -i virtual --duration 0.1", ("/nonexistent/x.dbc",)),
    # sim
    ("sim -i virtual --seed -1", ("--seed",)),
    ("sim -i virtual --duration 0", ("--duration",)),
    ("sim -i virtual --duration 0.1 --faults drop=-0.1", ("drop",)),
    ("sim -i virtual --robot nosuchbot", ("nosuchbot",)),
    ("sim --scenario nope", ("nope",)),
    ("sim -i virtual --duration 0.1 --bus-arg novalue", ("--bus-arg", "novalue")),
    # firmware
    ("firmware --integrator x", ("--integrator",)),
    ("firmware --duration 1e9", ("--duration",)),
    ("firmware -i virtual --duration 0.1 --faults babble=1e6", ("babble",)),
    ("firmware -i nosuchinterface --duration 0.1", ("nosuchinterface",)),
    # vectors
    ("vectors --seed -1 --out {tmp}/v", ("--seed",)),
    ("vectors --duration 0 --out {tmp}/v", ("--duration",)),
    ("vectors --duration 1e6 --out {tmp}/v", ("--duration", "3600")),
    ("vectors", ("--out",)),
    ("vectors --out {tmp}/missing --check", ("missing",)),
    ("vectors --out /proc/x/v", ("--out /proc/x/v",)),
    # busload
    ("busload -b 123", ("123", "CAN bitrate")),
    ("busload --add X:1:2", ("X:1:2",)),
    ("busload --add HOG:0x050:9:10", ("HOG",)),
    ("busload --dbc {tmp}/missing.dbc", ("missing.dbc",)),
    ("busload -b 10000", ("100",)),
    ("busload --report /proc/x/b.json", ("/proc/x/b.json",)),
    # key
    ("key derive --fleet-key {tmp}/missing.key --robot r1 --out {tmp}/r1.key", ("missing.key",)),
    ("key derive --fleet-key {text} --robot r1 --out {tmp}/r1.key", ("notes.txt", "10 bytes")),
    ("key derive --fleet-key {text} --robot r1 --out {tmp}/no/r1.key", ("notes.txt",)),
    ("key derive --robot r1 --out {tmp}/r1.key", ("--fleet-key",)),
    ("key rotate --fleet-key {text} --robot r1 --out {tmp}/r1.key", ("rotate",)),
    # bridge
    ("bridge --name bad/name", ("bad/name",)),
    ("bridge --duration 0", ("--duration",)),
    ("bridge --duration 1e12", ("--duration",)),
    ("bridge --broker mqtts://example.org --ca /nonexistent/ca.pem", ("--ca",)),
    ("bridge --publish-hz 0", ("--publish-hz",)),
    ("bridge --integrator x", ("--integrator",)),
    # fleet
    ("fleet --robots 100000", ("--count/--robots", "100000")),
    ("fleet -n 0", ("0",)),
    ("fleet --count 2 --max-miss-ratio -1", ("--max-miss-ratio", "-1")),
    ("fleet --max-miss-ratio 2", ("--max-miss-ratio",)),
    ("fleet --duration 1e12", ("--duration",)),
    ("fleet --seed -1", ("--seed",)),
    ("fleet -n 2 --seed 4294967295", ("--seed", "2^32")),
    ("fleet --report /proc/x/f.json", ("--report /proc/x/f.json",)),
    ("fleet --report /dev/full", ("--report /dev/full",)),
    ("fleet --robot nosuchbot", ("nosuchbot",)),
    ("fleet --workers 0", ("--workers", "0")),
    ("fleet --workers -2", ("--workers", "-2")),
    ("fleet -n 2 --workers 3", ("--workers 3", "robots", "2")),
    ("fleet -n 5 --shard 1/2 --workers 3", ("--workers 3", "robots", "(2)")),
    ("fleet --shard 3", ("--shard", "K/N")),
    ("fleet --shard a/b", ("--shard", "K/N")),
    ("fleet --shard 0/2", ("--shard", "K must be in [1, 2]")),
    ("fleet --shard 3/2", ("--shard", "K must be in [1, 2]")),
    ("fleet --shard 1/0", ("--shard", "N must be in")),
    ("fleet -n 1 --shard 1/2", ("--shard 1/2", "no robot left")),
    ("fleet --port 0", ("--port", "0")),
    ("fleet --port 70000", ("--port", "70000")),
    ("fleet --broker mqtt://127.0.0.1:1 --port 1883", ("--port", "--broker")),
    ("fleet -n 4 --shard 2/2", ("--shard needs --broker: the shards of one fleet meet on one "
                                "broker",)),
    # experiment
    ("experiment seed002 --runs 1000000", ("--runs", "1000000")),
    ("experiment seed002 --runs 0", ("--runs",)),
    ("experiment seed002 --seed -1", ("--seed",)),
    ("experiment seed002 --misalign 90", ("--misalign",)),
    ("experiment nope", ("nope",)),
    ("experiment seed002 --report /proc/x/r.json", ("--report /proc/x/r.json",)),
    # umbmark
    ("umbmark --runs 0", ("--runs",)),
    ("umbmark --side -1", ("--side",)),
    ("umbmark --errors ed=x", ("ed",)),
    ("umbmark --report /dev/full", ("--report /dev/full",)),
    # calibrate
    ("calibrate --method nope", ("nope",)),
    ("calibrate --runs 1000000", ("--runs",)),
    ("calibrate --seed 4294967296", ("--seed",)),
    # the top level
    ("", ("COMMAND",)),
    ("nosuchcommand", ("nosuchcommand",)),
]


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """A scratch directory and the input files the table refers to."""
    tmp = tmp_path_factory.mktemp("contract")
    foreign = tmp / "foreign.log"
    foreign.write_text(
        "".join(f"({i * 0.01:.6f}) can0 123#DEADBEEF{i % 256:02X}\n" for i in range(500))
    )
    empty = tmp / "empty.log"
    empty.write_text("")
    text = tmp / "notes.txt"
    text.write_text("not a log\n")
    good, corrupt = tmp / "good.log", tmp / "corrupt.log"
    assert main(["run", "--duration", "2", "--log", str(good)]) == 0
    corrupt.write_text(_corrupt_encoder_checksums(good.read_text()))
    return {"tmp": str(tmp), "foreign": str(foreign), "empty": str(empty), "text": str(text),
            "corrupt": str(corrupt)}


def _corrupt_encoder_checksums(candump: str) -> str:
    """Every WHEEL_ENCODERS frame with its CHECKSUM byte inverted (all fail E2E)."""
    lines = []
    for line in candump.splitlines():
        stamp, channel, frame, *rest = line.split()
        can_id, data = frame.split("#")
        if can_id == "100":
            data = f"{int(data[:2], 16) ^ 0xFF:02X}{data[2:]}"
        lines.append(" ".join([stamp, channel, f"{can_id}#{data}", *rest]))
    return "\n".join(lines) + "\n"


def test_the_table_covers_every_subcommand() -> None:
    assert len(BAD) >= 60
    covered = {argv.split()[0] for argv, _ in BAD if argv}
    assert covered >= set(SUBCOMMANDS)


@pytest.mark.parametrize(("argv", "words"), BAD, ids=[a or "(none)" for a, _ in BAD])
def test_bad_invocation_is_one_error_line_and_exit_2(
    argv: str, words: tuple[str, ...], files: dict[str, str], capsys: pytest.CaptureFixture[str]
) -> None:
    code = main([part.format(**files) for part in argv.split()])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err
    lines = err.splitlines()
    assert len([x for x in lines if x.startswith("error: ")]) == 1, err
    assert lines[-1].startswith("error: "), err
    assert len(lines) == 1, err
    for word in words:
        assert word in lines[-1], (word, lines[-1])


def test_a_report_that_fails_at_the_end_names_its_path_after_the_summary(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The up-front check waved through (as for a disk that fills during the run): the real
    ENOSPC of /dev/full at the end is one line naming the path, and the verdict is printed."""
    import odocan.host.report.summary as summary

    monkeypatch.setattr(summary, "check_writable", lambda path, option: None)
    code = main(["run", "--duration", "2", "--report", "/dev/full"])
    out, err = capsys.readouterr()
    assert code == 2
    assert err == "error: --report /dev/full: No space left on device\n"
    assert "PASS" in out
    assert "WHEEL_ENCODERS" in out


@pytest.mark.parametrize(
    "argv",
    [
        ["--debug", "run", "--seed", "-1"],
        ["run", "--debug", "--seed", "-1"],
        ["run", "--seed", "-1", "--debug"],
    ],
)
def test_debug_is_taken_anywhere_and_shows_the_exception(
    argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    """The traceback on stderr, but the same exit code: --debug must not turn 2 into 1."""
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback (most recent call last)" in err
    assert "UsageError" in err
    assert err.rstrip().splitlines()[-1].startswith("error: ")
    assert "--seed" in err


def test_debug_after_the_subcommand_runs_it(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", "--duration", "1", "--debug"]) == 0
    assert "PASS" in capsys.readouterr().out


@pytest.mark.parametrize("tolerance", ["1e-4", "1e-9"])  # a PASS, a FAIL
def test_a_closed_stdout_ends_quietly(tolerance: str) -> None:
    """``odocan run | head -1``: nothing on stderr (no BrokenPipeError, no 120), and exit 141
    (128 + SIGPIPE, as a writer killed by SIGPIPE): it was 0, so under ``set -o pipefail`` a
    FAILing drive piped to ``head`` read as a pass."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "odocan", "run", "--duration", "2", "--tolerance", tolerance],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "PYTHONDONTWRITEBYTECODE": "1"},
    )
    assert proc.stdout is not None
    assert proc.stderr is not None
    first = proc.stdout.readline()
    proc.stdout.close()  # as head -1 does
    err = proc.stderr.read()
    assert proc.wait(timeout=60) == 141, err
    assert first.startswith(b"odocan run:")
    assert err == b""


class _FailingListener(can.Listener):
    def on_message_received(self, msg: can.Message) -> None:
        pass

    def stop(self) -> None:
        raise OSError(28, "No space left on device")


def test_rig_close_releases_every_bus_when_a_listener_fails() -> None:
    from odocan.sim import robot
    from odocan.sim.rig import LockstepRig, RigConfig

    rig = LockstepRig(RigConfig(robot=robot.load("pmir"), channel="contract-close"),
                      listeners=[_FailingListener(), _FailingListener()])
    rig.step()
    with pytest.raises(OSError, match="No space"):
        rig.close()
    assert all(bus._is_shutdown for bus in rig._buses)
