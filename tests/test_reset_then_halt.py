"""An MCU reset with its receive FIFO cleared, then halted a few ticks later (issue #11: a FAIL
must never blame a correct firmware).

The rig (``tests.fault_rig.FaultRig``): pmir drives from tick 0; its MCU is reset at tick
``AT`` with the FIFO drained (as in ``tests/test_reprime_count_second_life.py``: its first tick
has no encoder frame, INIT) and runs ``lag`` ticks before it halts ``halted`` ticks (that test
halts it at the reset: ``lag`` 0). The truth, by the tests' float64 odometry
(``tests.independent_checker._Odometry``) of cantools-decoded frames: the new firmware primes
on frame ``AT + 1``, steps each frame to ``AT + lag`` in real time, takes the two frames its
FIFO kept (``AT + lag + 1``, ``AT + lag + 2``: ``f``) when it resumes, and, the stall long
enough (600 or 1000 ticks), re-primes on the resumed frame ``r = AT + lag + halted + 2``; its
first count page's ENC_E2E_LOST is ``(r - f - 1) mod 16``. At ``lag`` 2 and more it sends a pose
before the stall (lag 1: none, the stall-before-the-first-pose case).

Before, with ``lag`` 2 or 3 on the circle halted 600 ticks: ``analyze`` FAILed the correct
firmware by 42 mm / 47 mrad on the whole log (the life split took the start its first count
page counts, 593 frames late: the page misses the frames the FIFO overran; the stall before
the first pose was the only one that vetoed it, ``reboots.stalled_first``) and by 5 mm on a log
starting at the reset (the power-up's tick bound, 11 frames from the log's first, met
ENC_E2E_OK 11 by chance: the reference primed a frame early, ``stallpowerup.log_power_up``); the
streamed ``analyze`` likewise; live on the log from the reset the monitor said DISTANCE WRONG
and the bridge FAILed (the same tick bound, ``sources.SourceWatch.on_page``) while the fleet
PASSed (it said ODOM_TWIST beside its verdict: ``fleetjudge.watched_verdict``).
"""

from __future__ import annotations

import itertools
import math
from functools import cache
from pathlib import Path
from typing import Any

import can
import pytest

from odocan.firmware import frames as fr
from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import HEADING_LSB_RAD, POSITION_LSB_M, analyze
from odocan.sim.board import TICK_S
from odocan.sim.scenarios import get_scenario
from tests.fault_rig import FaultRig
from tests.sweeps import sample
from tests.test_first_second_reboot import _decoded, _reencoded, _written, _wrong
from tests.test_reprime_count_second_life import _after_reprime, _encoders, _path
from tests.test_stall_before_first_pose_after_reboot import _live
from tests.test_stall_beyond_window import PMIR, _end_verdicts

AT = 500  # the reset's tick (5 s)
REPRIMED = (600, 1000)  # halts long enough to re-prime (COUNTER_RESET); 300 merges
GRID = list(itertools.product(("circle", "random", "spin"), (1, 2, 3, 4), (300, 600, 1000)))
FOUND = [("circle", 2, 600), ("circle", 3, 600)]  # the helper's false FAILs


@cache
def drive(scenario: str, lag: int, halted: int) -> tuple[can.Message, ...]:
    """The module docstring's log, from tick 0 to 5 s after the MCU resumed."""
    heard: list[can.Message] = []
    with FaultRig(scenario=get_scenario(scenario, PMIR, duration_s=60.0)) as rig:
        def reset(k: int) -> None:
            if k == AT:
                rig.board.reboot()
                while rig.fw_bus.recv(0) is not None:  # the reset clears the receive FIFO
                    pass
        rig.observers.append(lambda _k, got: heard.extend(got))
        rig.before_board.append(reset)
        rig.halted = lambda k: AT + lag < k <= AT + lag + halted
        rig.run((AT + lag + halted) * TICK_S + 5.0)
    return tuple(heard)


def _logged(messages: tuple[can.Message, ...], start: str) -> tuple[can.Message, ...]:
    """The whole log, or the part a recorder started at the reset heard."""
    return messages if start == "whole" else tuple(
        m for m in messages if m.timestamp >= AT * TICK_S)


def _off(messages: tuple[can.Message, ...], f: int, r: int, k: int) -> tuple[float, float]:
    """How far (m, rad) the new life's ``k``-th pose lies from the checker's odometry primed
    on ``AT + 1``, stepped to ``f``, re-primed on ``r`` (``_path``; a pose before the stall:
    stepped to the frame it names)."""
    named, x, y = _after_reprime(messages, AT)[k]
    odo = _path(_encoders(messages), AT + 1, min(f, named), r if named >= r else named, named)
    sx, sy = _decoded(x), _decoded(y)
    turn = math.remainder(odo.heading - sx["HEADING"] * math.tau / 65536, math.tau)
    return math.hypot(odo.x - sx["X"] * 1e-4, odo.y - sy["Y"] * 1e-4), abs(turn)


def _count(messages: tuple[can.Message, ...]) -> int:
    pages = [_decoded(m) for m in messages if m.arbitration_id == fr.ODOM_STATUS_ID
             and m.timestamp >= AT * TICK_S]
    return next(int(p["ENC_E2E_LOST"]) for p in pages if "ENC_E2E_LOST" in p)


@pytest.mark.parametrize(("scenario", "lag", "halted"),
                         [(s, lag, h) for s, lag, h in GRID if lag >= 2 and h in REPRIMED])
def test_what_the_firmware_did(scenario: str, lag: int, halted: int) -> None:
    """Primed on ``AT + 1``, stepped in real time to ``AT + lag`` (its poses before the stall
    on that path), its FIFO's two frames stepped, re-primed on the resumed frame: within an
    LSB over its first poses after (the pairs one frame off either way: beyond); its count page
    says that pair."""
    messages = drive(scenario, lag, halted)
    f, r = AT + lag + 2, AT + lag + halted + 2
    assert _count(messages) == (r - f - 1) % 16 == (halted - 1) % 16
    poses = _after_reprime(messages, AT)
    before = [k for k, (named, _, _) in enumerate(poses) if named <= AT + lag]
    after = next(k for k, (named, _, _) in enumerate(poses) if named >= r)
    assert before
    assert poses[after][0] - r in (0, 1)  # (poses every other frame)
    for k in [*before, after, after + 1, after + 20]:
        pos_m, turn_rad = _off(messages, f, r, k)
        assert pos_m <= POSITION_LSB_M, (k, pos_m)
        assert turn_rad <= HEADING_LSB_RAD, (k, turn_rad)
    pos_m, turn_rad = _off(messages, f - 1, r - 1, after + 1)  # the pair one frame early
    assert pos_m > POSITION_LSB_M or turn_rad > HEADING_LSB_RAD


def _analyze_verdicts(messages: tuple[can.Message, ...], path: Path) -> tuple[bool, int]:
    """``analyze``'s whole verdict and the streamed one's exit code (0: PASS)."""
    _written(messages, path)
    whole = analyze(read_log(path), PMIR, "exact").passed
    return whole, main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                        "--stream", "always"])


LEFT = pytest.mark.xfail(strict=True, reason=(
    "live POSE WRONG: reset, halted 3 s from the tick after its priming (no pose before): its "
    "first pose after names a backlog frame no sample resolves, yet its half ends the silence "
    "(livefirst), so no stall is told and the reference runs fine through the merged step "
    "(0.3 mm); logged from the reset, the power-up's tick bound proves frame 0 (primed on 1: "
    "6 mm). Fixing the first broke test_reprime_count_live's late-recorder cases, vetoing the "
    "second left 29 power-up re-prime cases UNJUDGED live"))
LEFT_CASES = {("circle", "whole"), ("random", "whole"), ("circle", "from reset"),
              ("random", "from reset"), ("spin", "from reset")}  # lag 1, halted 300


def _grid() -> list[Any]:
    """``GRID`` by start, sampled (``tests.sweeps``: ``FOUND`` and the live false FAILs left
    marked, ``LEFT``, always in), those marked."""
    cases = itertools.product(GRID, ("whole", "from reset"))
    pins = [(case, start) for case in GRID for start in ("whole", "from reset")
            if case in FOUND or (case[1:] == (1, 300) and (case[0], start) in LEFT_CASES)]
    return [pytest.param(scenario, lag, halted, start, marks=[LEFT] if (lag, halted) == (1, 300)
                         and (scenario, start) in LEFT_CASES else [])
            for (scenario, lag, halted), start in sample(cases, 3, pins)]


@pytest.mark.parametrize(("scenario", "lag", "halted", "start"), _grid())
def test_the_correct_firmware_passes_every_judge(scenario: str, lag: int, halted: int,
                                                 start: str, tmp_path: Path) -> None:
    """The grid (lag 1..4, halts 300/600/1000, circle/random/spin, the whole log and the log
    from the reset): ``analyze`` whole and streamed PASS, the monitor says no wrong pose nor
    DISTANCE, the bridge's and the fleet's end verdicts PASS. Before: ``FOUND`` FAILed."""
    messages = _logged(drive(scenario, lag, halted), start)
    assert _analyze_verdicts(messages, tmp_path / "right.log") == (True, 0)
    monitor, bridge, end_s = _live(messages)
    assert monitor.health(end_s)["state"] not in ("POSE WRONG", "DISTANCE WRONG")
    assert _end_verdicts(bridge) in ((("PASS", "PASS"), ("UNJUDGED", "UNJUDGED"))
                                     if lag == 1 and start != "whole" else (("PASS", "PASS"),))


@pytest.mark.parametrize("start", ["whole", "from reset"])
@pytest.mark.parametrize(("scenario", "lag", "halted"), FOUND)
@pytest.mark.parametrize("from_pose", [0, 1])
@pytest.mark.parametrize("bias_lsb", [100, 10_000])
def test_a_pose_off_after_the_resume_fails_every_judge(
        scenario: str, lag: int, halted: int, start: str, from_pose: int, bias_lsb: int,
        tmp_path: Path) -> None:
    """X 10 mm or 1 m off from the first pose after the resume (its ``from_pose``-th on):
    ``analyze`` whole and streamed FAIL, the monitor says POSE WRONG, the bridge's and the
    fleet's end verdicts FAIL. The checker puts the correct firmware's pose within an LSB."""
    messages = _wrong(drive(scenario, lag, halted), AT + lag + 1, bias_lsb, from_pose)
    r = AT + lag + halted + 2
    after = next(k for k, (named, _, _) in enumerate(_after_reprime(messages, AT)) if named >= r)
    assert _off(messages, AT + lag + 2, r, after + from_pose)[0] > bias_lsb * 1e-4 * 0.99
    messages = _logged(messages, start)
    assert _analyze_verdicts(messages, tmp_path / "wrong.log") == (False, 1)
    monitor, bridge, end_s = _live(messages)
    assert monitor.health(end_s)["state"] == "POSE WRONG"
    assert _end_verdicts(bridge) == ("FAIL", "FAIL")


def _distance_off(messages: tuple[can.Message, ...], from_s: float, bias_m: float
                  ) -> tuple[can.Message, ...]:
    """ODOM_TWIST's DISTANCE ``bias_m`` longer from bus time ``from_s`` on (re-sealed)."""
    out = []
    for m in messages:
        if m.arbitration_id == fr.ODOM_TWIST_ID and m.timestamp >= from_s:
            signals = _decoded(m)
            signals["DISTANCE"] = round((signals["DISTANCE"] + bias_m) % 65.536, 3)
            m = _reencoded(m, signals, fr.ODOM_TWIST_DATA_IDS)
        out.append(m)
    return tuple(out)


@pytest.mark.parametrize("start", ["whole", "from reset"])
def test_a_distance_off_after_the_resume_fails_the_fleet_as_the_bridge(
        start: str, tmp_path: Path) -> None:
    """DISTANCE 20 mm long from the resume on (the poses right): ``analyze`` FAILs it, the
    monitor says DISTANCE WRONG, the bridge's end verdict FAILs, and the fleet's now too
    (before: PASS, ODOM_TWIST said beside its verdict; the disagreement the helper saw)."""
    lag, halted = FOUND[0][1:]
    wrong = _logged(_distance_off(drive("circle", lag, halted), (AT + lag + halted) * TICK_S,
                                  0.020), start)
    assert _analyze_verdicts(wrong, tmp_path / "long.log")[0] is False
    monitor, bridge, end_s = _live(wrong)
    assert monitor.health(end_s)["state"] == "DISTANCE WRONG"
    assert _end_verdicts(bridge) == ("FAIL", "FAIL")
