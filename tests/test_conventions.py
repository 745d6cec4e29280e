"""One heading convention and enums by name on every host output (issue 11, item 7).

``heading_rad`` is wrapped to (-pi, pi], ``heading_unwrapped_rad`` is cumulative; both are named on
MQTT (pose, reference, truth) and in the monitor's JSON. Enums (the firmware's STATE, INTEGRATOR,
REASON) go out by their DBC names. The expectations come from ``math.atan2`` and the DBC's value
tables, not from the code under test.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any

import can
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.host.protocol.pose import heading_fields, wrap_angle
from odocan.sim import robot
from odocan.sim.contract import database
from odocan.sim.rig import LockstepRig, RigConfig
from tests.synth_log import synthesize

PMIR = robot.load("pmir")
TURN = 2.0 * math.pi


def _atan2_wrap(angle_rad: float) -> float:
    """An independent (-pi, pi] wrap: atan2 gives [-pi, pi]; -pi is the same angle as +pi."""
    wrapped = math.atan2(math.sin(angle_rad), math.cos(angle_rad))
    return math.pi if wrapped == -math.pi else wrapped


@given(st.floats(min_value=-1e4, max_value=1e4, allow_nan=False))
def test_wrap_angle_is_in_the_half_open_interval_and_keeps_the_angle(angle_rad: float) -> None:
    wrapped = wrap_angle(angle_rad)
    assert -math.pi < wrapped <= math.pi
    difference = abs(wrapped - _atan2_wrap(angle_rad))
    assert min(difference, TURN - difference) < 1e-9  # the same angle (+pi and -pi coincide)
    fields = heading_fields(angle_rad)
    assert fields["heading_unwrapped_rad"] == angle_rad
    turns = (fields["heading_unwrapped_rad"] - fields["heading_rad"]) / TURN
    assert abs(turns - round(turns)) < 1e-9


def test_wrap_angle_at_the_bounds() -> None:
    assert wrap_angle(math.pi) == math.pi
    assert wrap_angle(-math.pi) == math.pi  # the open end goes to the closed one
    assert wrap_angle(3 * math.pi) == math.pi
    assert wrap_angle(6.28) < 0  # the truth's 6.28 rad of the issue is just below one turn


def _check_headings(payload: dict[str, Any]) -> float:
    """Both headings present and consistent; the unwrapped one returned."""
    assert -math.pi < payload["heading_rad"] <= math.pi
    turns = (payload["heading_unwrapped_rad"] - payload["heading_rad"]) / TURN
    assert abs(turns - round(turns)) < 1e-9
    return float(payload["heading_unwrapped_rad"])


def _enum_signals() -> dict[str, dict[int, str]]:
    """ODOM_STATUS signals with a DBC value table, by their lower-case key."""
    message = database().get_message_by_name("ODOM_STATUS")
    return {s.name.lower(): {int(k): str(v) for k, v in s.choices.items()}
            for s in message.signals if s.choices and s.name not in ("PAGE",)}


def test_mqtt_and_monitor_name_both_headings_and_the_enums_over_two_turns() -> None:
    """A spin of two turns: the truth on MQTT stays in (-pi, pi] (it was 6.28 rad, SIM_TRUTH's
    [0, 2 pi)), its cumulative heading reaches two turns like the on-board one, and the
    firmware's status says ``"state": "OK"``, not 1."""
    telemetry = RobotTelemetry("r", Geometry.of(PMIR), "exact", counter_bits=PMIR.counter_bits,
                               publish_hz=10)
    monitor = BusMonitor(PMIR, "exact")
    out: list[tuple[str, dict[str, Any]]] = []
    last_s = [0.0]

    class Feed(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            out.extend(telemetry.feed(msg))
            monitor.feed(msg, now_s=msg.timestamp)
            last_s[0] = msg.timestamp

    config = RigConfig(robot=PMIR, seed=3, channel="test-conventions", scenario="spin")
    with LockstepRig(config, [Feed()]) as rig:
        rig.run()
    by_leaf: dict[str, list[dict[str, Any]]] = {}
    for leaf, payload in out:
        by_leaf.setdefault(leaf, []).append(payload)
    for leaf in ("pose", "reference", "truth"):
        unwrapped = [_check_headings(p) for p in by_leaf[leaf]]
        assert max(abs(h) for h in unwrapped) > 1.9 * TURN, leaf  # cumulative: two turns
        assert all(abs(b - a) < math.pi for a, b in itertools.pairwise(unwrapped))
    assert abs(by_leaf["truth"][-1]["heading_unwrapped_rad"]
               - by_leaf["pose"][-1]["heading_unwrapped_rad"]) < 0.05
    for payload in by_leaf["error"]:
        assert -math.pi < payload["pose_vs_reference"]["dheading_rad"] <= math.pi

    summary = telemetry.status()[1]["firmware"]["summary"]
    enums = _enum_signals()
    named = {key: value for key, value in summary.items() if key in enums}
    assert named["state"] == "OK"
    assert {"state", "integrator"} <= set(named)
    assert all(value in enums[key].values() for key, value in named.items())

    snapshot = monitor.snapshot(now_s=last_s[0])
    for key in ("pose", "reference", "truth"):
        _check_headings(snapshot[key])
    assert abs(snapshot["pose"]["heading_unwrapped_rad"]) > 1.9 * TURN
    assert isinstance(monitor.status.get("state"), str)


def test_the_report_names_both_headings(tmp_path: Path) -> None:
    """``final_onboard_pose`` of a spin past two turns: wrapped and cumulative, both named."""
    steps = 4_000
    synth = synthesize(PMIR, "exact", np.full(steps, -5), np.full(steps, 5))
    analysis = analyze(read_log(synth.write(tmp_path / "spin.log")), PMIR)
    final = analysis.report["final_onboard_pose"]
    unwrapped = _check_headings(final)
    assert unwrapped == pytest.approx(synth.state[-1].pose[2], abs=1e-4)
    assert unwrapped > 2 * TURN
    series = analysis.series  # the exported series: the same two names, the same convention
    for who in ("onboard", "reference"):
        wrapped, cumulative = series[f"{who}_heading_rad"], series[f"{who}_heading_unwrapped_rad"]
        assert np.all((wrapped > -math.pi) & (wrapped <= math.pi)), who
        assert np.abs(np.remainder(cumulative - wrapped + math.pi, TURN) - math.pi).max() < 1e-9
        assert cumulative[-1] > 2 * TURN
