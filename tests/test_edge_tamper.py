"""A step at the edge of a stall or a gap is no re-placement (issue #11, rule 5).

The outside trial's edit: +10 mm on the recorded ODOM_POSE_X of every pose from the first one
after a stall or a gap of the log on (``tests/log_edit.raise_raw``, each frame re-signed by
cantools), kobuki, scenario random:

- seed 269, ``delay=0.1:15,busoff=2:0.5,stall=5:1``, the step from the first pose after the
  1 s stall (6.00 s): the whole log's judge FAILs it by the resume rule
  (``stallfirst.resume_across``: 6.3 mm beyond every pose the firmware can resume at), but the
  streamed judge (``--stream always``) ran the neighbours' rule alone
  (``stream_stallfirst.stream_first`` dropped the stalls' breaks) and PASSed it;
- seed 185, ``stall=3:1,drop=0.05``, the step from the first pose after the stall (4.00 s):
  the re-placement's bound there is under 2 mm (+1 mm PASSes, as it may; +2 mm FAILs);
- seed 241, ``delay=0.3:55,busoff=1:1,drop=0.05``, the step from the first pose after the bus-off
  (2.06 s; a gap of the log: no frame logged from 1.0 to 2.0 s): its bound is under 1 mm.

Each FAILs every judge now; each drive untampered PASSes every one. The pose after the stall or
the gap is found here from the log itself (python-can: the first ODOM_POSE_X after its longest
silence), not from odocan.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import can
import pytest

from tests.log_edit import raise_raw

POSE_X = (2, 4)  # ODOM_POSE_X's X: bytes 2..5, signed, 0.1 mm
POSE_X_ID = 0x200  # ODOM_POSE_X (512)
JUDGES = ["auto", "always", "never"]
DRIVES = {
    "stall_delay_busoff": ["--seed", "269", "--faults", "delay=0.1:15,busoff=2:0.5,stall=5:1"],
    "stall_drop": ["--seed", "185", "--faults", "stall=3:1,drop=0.05"],
    "busoff_delay_drop": ["--seed", "241", "--faults", "delay=0.3:55,busoff=1:1,drop=0.05"],
}
# the edge each drive's step starts at: (the silence's least length s, its end's earliest time s)
EDGES = {"stall_delay_busoff": (0.9, 5.5), "stall_drop": (0.9, 3.5),
         "busoff_delay_drop": (0.9, 1.5)}


def _odocan(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "odocan", *args], capture_output=True,
                          text=True, check=False)


def _analyze(log: Path, stream: str, report: Path | None = None
             ) -> subprocess.CompletedProcess[str]:
    extra = [] if report is None else ["--report", str(report)]
    return _odocan("analyze", str(log), "--robot", "kobuki", "--stream", stream, *extra)


def first_pose_after_silence(log: Path, silence_s: float, after_s: float) -> float:
    """The time (s after the log's first frame) of the first ODOM_POSE_X at or after
    ``after_s`` that follows a silence of ODOM_POSE_X of ``silence_s`` or more."""
    first = previous = None
    with can.LogReader(str(log)) as reader:
        for msg in reader:
            first = msg.timestamp if first is None else first
            if msg.arbitration_id != POSE_X_ID:
                continue
            t_s = msg.timestamp - first
            if previous is not None and t_s >= after_s and t_s - previous >= silence_s:
                return t_s
            previous = t_s
    raise AssertionError(f"no pose after a {silence_s} s silence in {log}")


@pytest.fixture(scope="module", params=sorted(DRIVES))
def drive(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
          ) -> tuple[str, Path]:
    name = str(request.param)
    log = tmp_path_factory.mktemp(name) / "clean.log"
    done = _odocan("run", "--robot", "kobuki", "--scenario", "random", "--duration", "10",
                   *DRIVES[name], "--log", str(log))
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    return name, log


@pytest.fixture(scope="module")
def stepped(drive: tuple[str, Path], tmp_path_factory: pytest.TempPathFactory) -> Path:
    name, log = drive
    at_s = first_pose_after_silence(log, *EDGES[name])
    out = tmp_path_factory.mktemp(name + "_step") / "step.log"
    assert raise_raw(log, out, "ODOM_POSE_X", POSE_X, 100, at_s - 1e-4) > 100  # +10 mm
    return out


@pytest.mark.parametrize("stream", JUDGES)
def test_a_10_mm_step_from_the_first_pose_after_a_stall_or_gap_fails(stepped: Path,
                                                                       stream: str) -> None:
    done = _analyze(stepped, stream)
    assert done.returncode == 1, done.stdout[-2000:]


@pytest.mark.parametrize("stream", JUDGES)
def test_the_untampered_drives_pass(drive: tuple[str, Path], stream: str) -> None:
    done = _analyze(drive[1], stream)
    assert done.returncode == 0, done.stdout[-2000:]


def test_both_judges_judge_the_resume_after_the_stall(drive: tuple[str, Path],
                                                      tmp_path: Path) -> None:
    """The streamed judge runs the resume rule as the whole log's does: the same stall first
    pose verdict in both reports (it ran no resume at all before: 0 against 1)."""
    said = []
    for stream in ("never", "always"):
        report = tmp_path / f"{stream}.json"
        assert _analyze(drive[1], stream, report).returncode == 0
        said.append(json.loads(report.read_text())["stall_first_pose"])
    assert said[0] == said[1]
