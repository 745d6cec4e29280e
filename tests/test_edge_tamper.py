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

from tests.judges_cli import raise_first_x, raise_x_10_mm
from tests.test_live_reboot import bridge_of, monitor_of

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
    assert raise_x_10_mm(log, out, at_s - 1e-4) > 100
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


# One wrong frame under a reordering, duplicating bus (the trial's second edit): +10 mm on a
# single ODOM_POSE_X. Of kobuki seed 3's poses (random, 10 s, delay=0.3:55,dup=0.1) the judge
# compares 303 of the 419 with a half the host's E2E accepted (72 %): 214 pairs and 89 of 205
# lone halves (the partner refused as out of sequence). Of the other 116 lone halves, 82 name a
# frame in a segment of the reference without a kept sample (``lonehalves.budgets``: the host
# refused 291 of 1107 encoder frames as out of sequence, each refusal opening a segment, and
# under a reordering bus such a segment's frames may not be the firmware's); 34 may name a later
# frame of the same ENC_COUNTER that the host refused (``resendalias``: one came between it and
# the frame it was matched to), follow a silence or lie outside the reference. Ten single-frame
# edits from 0.55 s every 0.93 s: 7 FAILed; two hit an X the host's E2E refused as out of
# sequence (as any Profile 2 receiver would: no consumer takes that pose), one (6.136 s) a lone X
# that may alias so (ENC_COUNTER 0: the host has no reference at the refused frame it may name)
# PASSed. Those 116 are now judged against every frame they may name (``candidates``: 419 of
# 419 judged); the one at 6.136 s FAILs by its 10 mm.
REORDER_DRIVE = ["--robot", "kobuki", "--scenario", "random", "--duration", "10", "--seed", "3",
                 "--faults", "delay=0.3:55,dup=0.1"]


@pytest.fixture(scope="module")
def reordered(tmp_path_factory: pytest.TempPathFactory) -> Path:
    log = tmp_path_factory.mktemp("reorder") / "clean.log"
    done = _odocan("run", *REORDER_DRIVE, "--log", str(log))
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    return log


def test_a_10_mm_lone_x_that_may_alias_fails(reordered: Path, tmp_path: Path) -> None:
    """A lone ODOM_POSE_X (its Y refused out of sequence) that may name a later frame of its
    ENC_COUNTER the host refused (resendalias) was counted unjudged and +10 mm on it PASSed
    (the X at 6.136 s; 116 of 419 poses unjudged). Judged against every frame it may name
    (``candidates``), it FAILs by the edit, whole and streamed."""
    out = tmp_path / "once.log"
    raise_first_x(reordered, out, 100, 6.13, 6.14)
    for stream in ("never", "always"):
        report = tmp_path / f"once.{stream}.json"
        assert _analyze(out, stream, report).returncode == 1, stream
        beyond = json.loads(report.read_text())["onboard_vs_reference"][
            "max_position_error_beyond_allowance_m"]
        assert beyond > 0.009


@pytest.mark.xfail(strict=True, reason=(
    "the live judges leave a lone X unjudged where a placement is due (livelone: a gap of "
    "the log since the last sample, StallPlacer.due; the sample before it names 439, it 441): "
    "the "
    "+10 mm X at 6.136 s (kobuki seed 3, delay=0.3:55,dup=0.1) leaves the monitor and the "
    "bridge OK (0 POSE WRONG, largest error 0.074 mm) where analyze FAILs it 9.92 mm by its "
    "candidates (host.judge.candidates); live candidate judging is not built"))
def test_the_live_judges_flag_a_10_mm_lone_x_that_may_alias(reordered: Path,
                                                           tmp_path: Path) -> None:
    out = tmp_path / "once.log"
    raise_first_x(reordered, out, 100, 6.13, 6.14)
    for judge in (monitor_of(out, "kobuki", "exact"), bridge_of(out, "kobuki", "exact")):
        judge.tracker.wrongs.finish(judge.tracker.allowance_m)
        assert judge.tracker.wrongs.count >= 1


def test_the_reordered_drive_passes(reordered: Path) -> None:
    for stream in ("never", "always"):
        done = _analyze(reordered, stream)
        assert done.returncode == 0, done.stdout[-2000:]
        assert "judged     419 of 419 on-board poses" in done.stdout  # none left unjudged


# Steps after a bus-off or a reordered stall (12 s drives, kobuki random; each untampered
# PASSes every judge):
# - seed 24, ``stall=2:0.5,stall=6:1.5,busoff=4:0.3``, +10 mm from the first pose after the
#   bus-off (4.32 s, a gap of the log: no frame logged for 0.3 s): the gap's allowance was 121.9
#   mm (``gapbound``: any split of the gap's 30 periods within the plausibility bound), 9.99 mm
#   absorbed, PASS: the pages around it (3.60 s, 4.80 s) count 88 frames accepted and one
#   refused (REPEATED), exactly the log's 89, all the host's, so the firmware took none of the
#   gap's and skipped one of the log's (``gapskips``: 0.04 mm); FAILs now.
# - seed 26 (still absorbed), ``delay=0.3:55,dup=0.1,stall=5:1``, +10 mm from the first pose
#   after the stall (6.02 s): the resume rule (``stallresume``) still finds a resume for the
#   first kept sample after it (0.12 mm inside its slack, 0.20 untampered: any merged step
#   p -> q of the 1 s stall is a candidate, so a shift along the path is another q), and the
#   first placement with a pose after the stall (16.68 mm asked) lies within the stall's merge
#   allowance (853.9 mm; the gaps since add 12 mm: 182 placements after gaps, 988.9 mm summed
#   by the end); PASS.
UNFIXED = {
    "busoff_gap": (["--seed", "24", "--faults", "stall=2:0.5,stall=6:1.5,busoff=4:0.3"],
                   (0.3, 4.0)),
    "delay_dup_stall": (["--seed", "26", "--faults", "delay=0.3:55,dup=0.1,stall=5:1"],
                        (0.9, 5.5)),
}


@pytest.fixture(scope="module", params=sorted(UNFIXED))
def unfixed(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
            ) -> tuple[Path, Path]:
    name = str(request.param)
    drive, edge = UNFIXED[name]
    base = tmp_path_factory.mktemp(name)
    done = _odocan("run", "--robot", "kobuki", "--scenario", "random", "--duration", "12",
                   *drive, "--log", str(base / "clean.log"))
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    at_s = first_pose_after_silence(base / "clean.log", *edge)
    assert raise_x_10_mm(base / "clean.log", base / "step.log", at_s - 1e-4) > 100
    return base / "clean.log", base / "step.log"


def test_the_unfixed_drives_pass_untampered(unfixed: tuple[Path, Path]) -> None:
    for stream in ("never", "always"):
        done = _analyze(unfixed[0], stream)
        assert done.returncode == 0, done.stdout[-2000:]


def test_a_10_mm_step_after_a_bus_off_or_a_reordered_stall_fails(
        unfixed: tuple[Path, Path], request: pytest.FixtureRequest) -> None:
    if unfixed[0].parent.name.startswith("delay_dup_stall"):
        request.applymarker(pytest.mark.xfail(strict=True, reason=(
            "absorbed by the stall's placement, not a gap's: kobuki 26 delay=0.3:55,dup=0.1,"
            "stall=5:1 (the resume rule finds a merged step that reaches the shifted pose, 0.12 "
            "mm inside its slack; the first placement with a pose after the stall, 6.005 s, asks "
            "16.68 mm within 866 mm, 853.9 mm of it the 1 s stall's merge allowance: no page "
            "proves which of the stall's frames the firmware took; the 13-period gap there "
            "11.45 mm; 988.9 mm summed by the end)")))
    for stream in ("never", "always"):
        assert _analyze(unfixed[1], stream).returncode == 1, stream
