"""``analyze --dbc OTHER`` and ``monitor --dbc OTHER`` judge with OTHER's bus facts (rule 3).

OTHER here is dbc/odocan.dbc with every ``GenMsgCycleTime`` doubled (WHEEL_ENCODERS at 20 ms,
the poses at 40, ODOM_STATUS at 200), and the firmware that speaks it is odocan's on a 20 ms tick
(its tick, its encoder period, its navigation period and its periods per second patched before
it is imported), driven by the lockstep rig with ``ODOCAN_DBC=OTHER``. Its log is then judged in
a fresh process that never had ``ODOCAN_DBC`` set, as a user would judge it. The tests' own
float64 checker (at OTHER's 20 ms period) says which firmware is right: the correct one, and one
whose ODOM_POSE_X ``X`` is 2 LSB off. Before, the judges held odocan's DBC's 10 ms while
decoding with OTHER and FAILed the correct firmware (a 397 mm "error" after two phantom counter
restarts). Where the judges of a process were loaded already (``main()`` called in this pytest
process), a DBC whose facts differ is refused in one line naming the fact.
"""

from __future__ import annotations

import io
import os
import re
import subprocess
import sys
from collections.abc import Callable
from contextlib import redirect_stdout
from pathlib import Path

import pytest

import odocan
from odocan.host.cli import main
from odocan.sim.robot import load
from tests.independent_checker import Robot, check

ROOT = Path(__file__).resolve().parents[1]
DBC = ROOT / "dbc" / "odocan.dbc"
TREE = Path(odocan.__file__).resolve().parents[1]
KOBUKI = load("kobuki")
PERIOD_S = 0.02  # OTHER's WHEEL_ENCODERS cycle
OFF_LSB = 2

# The lockstep rig with odocan's firmware on a 20 ms tick; ODOM_POSE_X's X off by argv[2] LSB
DRIVE = """
import sys
import odocan.firmware.hal as hal
hal.TICK_PERIOD_US = 20_000
import odocan.firmware.config as config
config.ENCODER_PERIOD_US = 20_000
import odocan.firmware.nav as nav
nav.NAV_PERIOD_MS = 40
import odocan.firmware.restartage as restartage
restartage.PERIODS_PER_S = 50
from odocan.firmware import frames
from odocan.host.cli import main
right, off = frames.pack_odom_pose_x, int(sys.argv[2])
frames.pack_odom_pose_x = lambda c, e, x, h, m: right(c, e, x + off, h, m)
sys.exit(main(["run", "--robot", "kobuki", "--duration", "6", "--seed", "1", "--firmware",
               "python", "--log", sys.argv[1]]))
"""

# ``odocan monitor --dbc`` on a virtual bus the log is played onto at its pace; SIGTERM (the
# monitor's normal end without --duration) once the monitor has judged every frame: its judge
# came back for more (``BusReader.get`` found nothing) after it had taken them all (a signal
# leaves the frames read and not taken unjudged: ``judge_pending``). Not a fixed wait: on a
# loaded machine the judge could still be behind 0.5 s after the bus was read.
MONITOR = """
import os, signal, sys, threading, time
import can
from can.interfaces import virtual
from odocan.host.io import busreader

CHANNEL = "dbc-other-%d" % os.getpid()
JUDGED_WITHIN_S = 60.0
taken = [0]  # frames the judge took (each judged before it asks for the next)
idle = threading.Event()  # set when the judge asked and nothing was left
get = busreader.BusReader.get

def judged_get(self, timeout_s):
    msg = get(self, timeout_s)
    if msg is None:
        idle.set()
    else:
        taken[0] += 1
    return msg

busreader.BusReader.get = judged_get

def play(log):
    sent = 0
    with can.Bus(interface="virtual", channel=CHANNEL, preserve_timestamps=True) as out:
        while len(virtual.channels.get(CHANNEL, [])) < 2:
            time.sleep(0.01)
        first = t0 = None
        for msg in can.LogReader(log):
            if first is None:
                first, t0 = msg.timestamp, time.monotonic()
            time.sleep(max(0.0, t0 + msg.timestamp - first - time.monotonic()))
            out.send(msg)
            sent += 1
        end = time.monotonic() + JUDGED_WITHIN_S
        while time.monotonic() < end:
            idle.clear()
            if taken[0] >= sent and idle.wait(max(0.0, end - time.monotonic())):
                break
            time.sleep(0.05)
    os.kill(os.getpid(), signal.SIGTERM)

threading.Thread(target=play, args=(sys.argv[1],), daemon=True).start()
from odocan.host.cli import main
sys.exit(main(["monitor", "-i", "virtual", "-c", CHANNEL, "--robot", "kobuki", "--dbc",
               sys.argv[2], "--json"]))
"""

ANALYZE = """
import sys
from odocan.host.cli import main
sys.exit(main(["analyze", sys.argv[1], "--robot", "kobuki", "--dbc", sys.argv[2]]))
"""


def _env(cache: Path, dbc: Path | None) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "ODOCAN_DBC"}
    env.update(PYTHONPATH=str(TREE), ODOCAN_CACHE_DIR=str(cache))
    if dbc is not None:
        env["ODOCAN_DBC"] = str(dbc)
    return env


def _python(script: str, *argv: Path, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", script, *map(str, argv)], env=env,
                          capture_output=True, text=True, check=False, timeout=300)


@pytest.fixture(scope="module")
def other(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """OTHER (every cycle doubled) and the logs of the firmware speaking it, right and off."""
    where = tmp_path_factory.mktemp("dbc-other")
    text, n = re.subn(r'(BA_ "GenMsgCycleTime" BO_ \d+) (\d+);',
                      lambda m: f"{m[1]} {2 * int(m[2])};", DBC.read_text(encoding="utf-8"))
    assert n >= 8
    paths = {"dbc": where / "slow.dbc", "cache": where / "cache"}
    paths["dbc"].write_text(text, encoding="utf-8")
    for off in (0, OFF_LSB):
        paths[f"off{off}"] = log = where / f"off{off}.log"
        done = _python(DRIVE, log, Path(str(off)), env=_env(paths["cache"], paths["dbc"]))
        assert done.returncode in (0, 1), done.stderr
        assert log.stat().st_size > 0
    return paths


def _checked(log: Path) -> bool:
    p = KOBUKI.firmware_params()
    robot = Robot(p["counts_per_rev"], p["wheel_radius_left_nm"], p["wheel_radius_right_nm"],
                  p["wheelbase_nm"], p["counter_bits"], p["max_wheel_speed_mm_s"])
    verdict = check(log, robot, "exact", lambda t_s: (0.0, 0.0, 0.0), period_s=PERIOD_S)
    assert verdict.samples >= 140  # 150 poses in 6 s at 40 ms: compared, not skipped
    return verdict.passed


def test_the_checker_tells_the_right_firmware(other: dict[str, Path]) -> None:
    assert _checked(other["off0"])
    assert not _checked(other[f"off{OFF_LSB}"])


@pytest.mark.parametrize("off", [0, OFF_LSB])
def test_analyze_dbc_judges_with_its_cycles(other: dict[str, Path], off: int) -> None:
    done = _python(ANALYZE, other[f"off{off}"], other["dbc"], env=_env(other["cache"], None))
    assert done.returncode == (0 if _checked(other[f"off{off}"]) else 1), done.stdout
    assert done.stderr == ""
    assert "re-primed" not in done.stdout  # no phantom counter restart at 10 ms periods
    verdict = done.stdout.strip().splitlines()[-1]
    assert verdict.startswith("PASS" if off == 0 else "FAIL: on-board vs reference"), verdict


@pytest.mark.parametrize("off", [0, OFF_LSB])
def test_monitor_dbc_judges_with_its_cycles(other: dict[str, Path], off: int) -> None:
    done = _python(MONITOR, other[f"off{off}"], other["dbc"], env=_env(other["cache"], None))
    assert done.returncode == (0 if _checked(other[f"off{off}"]) else 1), done.stderr
    if off:
        assert "the on-board pose was wrong" in done.stderr
        assert "397" not in done.stderr  # the 2 LSB, not the phantom restart's error
    else:  # one PASS line, nothing else
        assert done.stderr.startswith("monitor: PASS: ")
        assert done.stderr.count("\n") == 1


@pytest.mark.parametrize("argv", [
    ["analyze", "{log}"],
    ["analyze", "{log}", "{log}"],  # several logs: the batch
    ["monitor", "-i", "virtual", "-c", "dbc-other-refused", "--duration", "1"],
], ids=["analyze", "batch", "monitor"])
def test_a_dbc_the_loaded_judges_cannot_follow_is_refused(
    other: dict[str, Path], argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    # this process's judges hold odocan's DBC (10 ms): OTHER's 20 ms cannot be followed here
    argv = [a.format(log=other["off0"]) for a in argv]
    with redirect_stdout(io.StringIO()) as out:
        code = main([*argv, "--dbc", str(other["dbc"])])
    err = capsys.readouterr().err
    assert (code, out.getvalue()) == (2, "")
    assert err.count("\n") == 1, err
    assert err.startswith(f"error: --dbc {other['dbc']}: ")
    assert "GenMsgCycleTime (ms)" in err
    assert "in a process of its own" in err


def test_the_same_facts_are_followed_in_process(
    other: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    # a copy of odocan's DBC (another path, the same facts) judges as odocan's own
    same = other["dbc"].with_name("same.dbc")
    same.write_text(DBC.read_text(encoding="utf-8"), encoding="utf-8")
    with redirect_stdout(io.StringIO()):
        code = main(["analyze", str(other["off0"]), "--robot", "kobuki", "--dbc", str(same)])
    assert code == 1  # OTHER's log judged at 10 ms: not refused, and not passed either
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize(("edit", "said"), [
    (lambda text: text.replace(' 6 "PROFILE"', ""), "ODOM_STATUS PAGE has no value PROFILE"),
    (lambda text: text.replace("BO_ 256 WHEEL_ENCODERS: 8", "BO_ xyz WHEEL_ENCODERS: 8"),
     "malformed DBC"),
], ids=["a fact missing", "malformed"])
def test_a_dbc_the_judges_cannot_read_is_one_line_in_a_fresh_process(
    other: dict[str, Path], edit: Callable[[str], str], said: str
) -> None:
    bad = other["dbc"].with_name("bad.dbc")
    text = DBC.read_text(encoding="utf-8")
    assert edit(text) != text
    bad.write_text(edit(text), encoding="utf-8")
    done = _python(ANALYZE, other["off0"], bad, env=_env(other["cache"], None))
    assert (done.returncode, done.stdout) == (2, "")
    assert done.stderr.count("\n") == 1, done.stderr
    assert done.stderr.startswith("error: ")
    assert said in done.stderr
