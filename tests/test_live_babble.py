"""The live judges (the monitor, the MQTT bridge) on a busy bus, as ``analyze`` judges it (issue 11,
rules 5 and 6: one judge, not three).

* A babbler below WHEEL_ENCODERS holds the bus (``tests/test_babble_firmware.py``'s run): the
  poses the firmware made meanwhile come out in a burst. The live judges used to pair each with
  the latest encoder frame on the bus: 8.9 mm off a firmware that analyze PASSes at 0.067 mm, then
  a placement after a "stall" that kept 1.6 mm for good (226 mm on a 10 s babble). They now
  resolve every pose half with ``samples.match_encoder`` (the queued rule) on a window of the
  latest frames: the same samples, the same errors, and a wrong firmware still shows.
* A babbler that overflows the firmware's mailbox (``tests/test_judge_lossy.py``'s run): the
  firmware loses frames the bus carried and says how many (ENC_E2E_LOST); the live judges allow
  the position what analyze allows (``losses.loss_allowance``'s rule, revised as each page
  comes), never the heading, and a wrong firmware still shows beyond it. Limits, stated: after a
  stall the live judges place the position at the first pose after it where analyze fits the
  segment (within one LSB of each other), and they leave out analyze's tail rule (frames since
  the last page counted lost when a later summary says MAILBOX_OVERFLOW).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import HEADING_LSB_RAD, POSITION_LSB_M, Analysis, analyze
from odocan.host.judge.monitor import BusMonitor
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim.robot import load
from tests.test_babble_firmware import _biased_x, _run_log
from tests.test_judge_lossy import _run
from tests.test_live_reboot import bridge_of, monitor_of


def _judges(path: Path, robot: str, integrator: str) -> tuple[Analysis, BusMonitor,
                                                               RobotTelemetry]:
    return (analyze(read_log(path), load(robot), integrator), monitor_of(path, robot, integrator),
            bridge_of(path, robot, integrator))


@pytest.fixture(scope="module")
def babble_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _run_log(tmp_path_factory.mktemp("babble"))


@pytest.fixture(scope="module")
def lossy_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    log, _ = _run(tmp_path_factory.mktemp("lossy"))
    return log


def test_the_live_judges_pair_a_burst_as_analyze_does(babble_log: Path) -> None:
    analysis, monitor, bridge = _judges(babble_log, "pmir", "exact")
    offline = analysis.report["onboard_vs_reference"]
    print(f"\nanalyze {offline['max_position_error_m'] * 1e3:.4f} mm over "
          f"{analysis.report['samples']['onboard']} samples; live "
          f"{monitor.tracker.vs_reference.max_dpos_m * 1e3:.4f} mm, "
          f"{bridge.tracker.vs_reference.max_dpos_m * 1e3:.4f} mm")
    assert analysis.passed
    for tracker in (monitor.tracker, bridge.tracker):
        assert tracker.stall.stalls == 0  # the burst is not a stall: nothing placed again
        assert tracker.reference_starts == 1
        assert tracker.vs_reference.samples == analysis.report["samples"]["onboard"] > 140
        assert tracker.vs_reference.max_dpos_m == pytest.approx(
            offline["max_position_error_m"], abs=1e-12)
        assert tracker.vs_reference.max_dheading_rad == pytest.approx(
            offline["max_heading_error_rad"], abs=1e-12)
        assert tracker.vs_reference.latest["dpos_m"] == pytest.approx(
            analysis.series["position_error_m"][-1], abs=1e-12)
    assert monitor.health(now_s=analysis.report["sim_seconds"])["state"] != "POSE WRONG"


def test_a_wrong_pose_in_the_burst_shows_live_as_in_analyze(
    babble_log: Path, tmp_path: Path
) -> None:
    """Every X one LSB and a half off from the babble on, or one X three LSB off among the burst's
    catching-up poses (``test_babble_firmware.test_a_wrong_pose_in_the_burst_still_fails``)."""
    for name, pick, lsb in (("every", lambda k, t: t > 2.0, 2),
                            ("one", lambda k, t: 3.735 < t < 3.7405 and k % 3 == 0, 3)):
        wrong = tmp_path / f"{name}.log"
        assert _biased_x(babble_log, wrong, pick, lsb) >= 1
        analysis, monitor, bridge = _judges(wrong, "pmir", "exact")
        offline = analysis.report["onboard_vs_reference"]["max_position_error_m"]
        assert not analysis.passed
        for tracker in (monitor.tracker, bridge.tracker):
            assert tracker.vs_reference.max_dpos_m == pytest.approx(offline, abs=1e-12)
            assert tracker.vs_reference.max_dpos_m > 1.5 * POSITION_LSB_M


def test_the_live_judges_allow_the_losses_analyze_allows(lossy_log: Path) -> None:
    analysis, monitor, bridge = _judges(lossy_log, "kobuki", "exact")
    offline = analysis.report["onboard_vs_reference"]
    stalls = [e for e in analysis.report["events"] if e["kind"] == "firmware_stall"]
    print(f"\nanalyze: {offline}")
    assert analysis.passed
    assert offline["max_position_error_m"] > POSITION_LSB_M  # the allowance counts
    for tracker in (monitor.tracker, bridge.tracker):
        print(f"live: max {tracker.vs_reference.max_dpos_m}, beyond the allowance "
              f"{tracker.max_beyond_allowance_m}, allowance {tracker.allowance_m()}")
        assert tracker.vs_reference.samples == analysis.report["samples"]["onboard"]
        assert tracker.stall.stalls == len(stalls)
        assert tracker.vs_reference.max_dpos_m == pytest.approx(
            offline["max_position_error_m"], abs=POSITION_LSB_M)
        assert tracker.max_beyond_allowance_m <= POSITION_LSB_M  # a correct firmware: within
        assert tracker.max_beyond_allowance_m == pytest.approx(
            offline["max_position_error_beyond_allowance_m"], abs=POSITION_LSB_M)
        # the same spans, less analyze's tail (lost since the last page); but a span live is
        # worked out at its page with the frames samples had named by then (a frame named only
        # later still counts as one that may be lost), so it may be a little wider: 0.37957 mm
        # live vs 0.37819 mm on this drive once the rig put babble on the bus in time order
        assert 0.9 * offline["loss_allowance_m"] < tracker.allowance_m() <= (
            1.01 * offline["loss_allowance_m"])
        assert tracker.vs_reference.max_dheading_rad <= HEADING_LSB_RAD  # no allowance there
    assert monitor.snapshot(now_s=analysis.report["sim_seconds"])["error"]["pose_vs_reference"][
        "loss_allowance_m"] == monitor.tracker.allowance_m()


def test_a_wrong_firmware_shows_beyond_the_allowance_live(lossy_log: Path, tmp_path: Path) -> None:
    """0.5 mm off early in the lossy drive: beyond the allowance live as in analyze."""
    wrong = tmp_path / "early.log"
    assert _biased_x(lossy_log, wrong, lambda k, t: 1.0 < t < 1.5, 5) > 10
    analysis, monitor, bridge = _judges(wrong, "kobuki", "exact")
    offline = analysis.report["onboard_vs_reference"]
    assert not analysis.passed
    for tracker in (monitor.tracker, bridge.tracker):
        assert tracker.max_beyond_allowance_m > 3 * POSITION_LSB_M
        assert tracker.max_beyond_allowance_m == pytest.approx(
            offline["max_position_error_beyond_allowance_m"], abs=POSITION_LSB_M)
