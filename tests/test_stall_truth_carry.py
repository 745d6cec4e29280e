"""The on-board pose carried to a truth sample between two of its poses, in the on-board
pose's own frame (issue #11).

The evidence log of a sim SIGSTOPped 1 s (``tests/files/sim_sigstop_1s.blf``, kobuki) has its
truth samples on even encoder frames and the firmware's poses on odd ones: the judges carry the
next on-board pose back to the truth sample's frame by the reference's own motion over that one
frame. Judged as a robot bounded at 4 m/s (as its firmware was), the reference re-primes over the
stall (an ambiguous silence: FAIL, ``test_sender_stall_step``) and leaves its heading off the
firmware's; its one-frame step, added as it is, pointed elsewhere than the firmware's path:
``onboard_vs_truth`` 6.06 mm on a firmware 0.76 mm off the truth (and 0.76 mm judged at 2 m/s).
The figure is checked here against this file's own: the truth against the on-board pose that
names the same encoder frame, where there is one (decoded with cantools, nothing of the judges).
Judged at 1.0-1.2 m/s (below the wheels' 1.0+ m/s), the reference refuses the 9 frames a late
sim tick doubled, as a firmware bounded there would, and the two truth samples on such frames
are carried by the step it refused (13.7 mm): the figure of the firmware the profile describes,
not a pairing error; not tested here.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import can
import cantools
import pytest
from cantools.database.can import Database

from odocan.host.cli.app import main
from odocan.sim.contract import DBC_PATH
from odocan.sim.robot import load, to_toml

EVIDENCE = Path(__file__).parent / "files" / "sim_sigstop_1s.blf"


def _same_frame_error_m() -> tuple[float, int]:
    """The largest distance from a truth sample (named encoder frame c) to the on-board pose
    naming c sent next to it in the log (within a few poses), and how many truth samples had
    one (84 of 110: the others fall between two poses, where a judge must carry one)."""
    db = cantools.database.load_file(str(DBC_PATH))
    assert isinstance(db, Database)
    poses: list[tuple[int, float, float]] = []  # (ENC_COUNTER, x m, y m) in log order
    x_half: dict[int, float] = {}
    parts: dict[int, dict[int, float]] = {}
    truths: list[tuple[int, float, float, int]] = []  # (ENC_COUNTER, x, y, poses before it)
    with can.BLFReader(str(EVIDENCE)) as reader:
        for msg in reader:
            try:
                message = db.get_message_by_frame_id(msg.arbitration_id)
            except KeyError:
                continue
            if message.name not in ("ODOM_POSE_X", "ODOM_POSE_Y", "SIM_TRUTH"):
                continue
            s: dict[str, Any] = dict(db.decode_message(  # type: ignore[arg-type]
                msg.arbitration_id, bytes(msg.data), decode_choices=False))
            c = int(s["ENC_COUNTER"])
            if message.name == "ODOM_POSE_X":
                x_half[c] = float(s["X"])
            elif message.name == "ODOM_POSE_Y" and c in x_half:
                poses.append((c, x_half[c], float(s["Y"])))
            elif message.name == "SIM_TRUTH" and int(s["PART"]) < 2:
                heard = parts.setdefault(c, {})
                heard[int(s["PART"])] = float(s["X" if int(s["PART"]) == 0 else "Y"])
                if len(heard) == 2:
                    truths.append((c, heard[0], heard[1], len(poses)))
                    del parts[c]
    errors = [min(math.hypot(x - px, y - py) for pc, px, py in same)
              for c, x, y, k in truths
              if (same := [p for p in poses[max(k - 3, 0):k + 6] if p[0] == c])]
    return max(errors), len(errors)


@pytest.mark.parametrize("stream", ["never", "always"])
def test_the_truth_figure_does_not_follow_the_robots_bound(
    tmp_path: Path, stream: str, capsys: pytest.CaptureFixture[str]
) -> None:
    own_m, paired = _same_frame_error_m()
    assert paired == 84  # of 110 truth samples
    assert own_m < 0.001
    figures = {}
    for bound in (2.0, 4.0):  # both above the 1.0 m/s its wheels ran at
        robot = tmp_path / f"kobuki_{bound}.toml"
        robot.write_text(to_toml(dataclasses.replace(load("kobuki"), max_wheel_speed_m_s=bound)))
        report = tmp_path / f"{bound}.json"
        main(["analyze", str(EVIDENCE), "--robot", str(robot), "--stream", stream,
              "--report", str(report)])
        capsys.readouterr()
        figures[bound] = json.loads(report.read_text())["onboard_vs_truth"][
            "max_position_error_m"]
    for bound, figure in figures.items():
        # the judge's figure also has the 26 carried samples: one step's rounding more at most
        assert own_m <= figure < own_m + 1e-4, (bound, figure, own_m)
