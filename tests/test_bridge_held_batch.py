"""A wrong sample in a batch the live judge releases at once is published (issue #11;
``host.mqtt.errorbatch``).

After an unseen controller restart the live judge holds the new start's samples for a second
(``host.judge.livenewstart``) and judges them together by the fit made of them. The bridge
published the last of the batch alone: on the straight 32-bit drive of
``tests/test_live_unseen_restart.py`` with the firmware's X 3 LSB off at one pose in that second,
51 samples came out at once and no ``error`` named the wrong one (its last sample right:
``pose_wrong`` false). Now that ``error`` carries ``since_last``: the samples since the previous
``error``, how many were wrong and the worst, read back as the broker gets it (``topics.dumps``).

The wrong sample is the firmware's by this file's own float64 odometry: the live reference at
that frame is within half an LSB of ``tests.independent_checker``'s (the test's ``_own_errors``),
so the on-board pose is more than 2 LSB off it.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.host.mqtt.topics import dumps
from tests.test_live_unseen_restart import DRIVES, _live, _log, _own_errors
from tests.test_stall_bound import _messages

DRIVE = DRIVES["straight32"]
WRONG_FRAME = 420  # 20 frames into the new start (400): inside its hold
BIAS_LSB = 3


def _errors(tmp_path: Path, bias: bool, publish_hz: float) -> tuple[list[dict[str, Any]], int]:
    """The ``error`` payloads as published (JSON read back), and the wrong frame's seq."""
    key, frames = ("x_bias_100um", {WRONG_FRAME: BIAS_LSB}) if bias else ("", None)
    live = _live(_log(tmp_path, DRIVE, key, frames), DRIVE)
    assert live.monitor.tracker.newstart.holds_made == 1  # the premise: the new start's hold
    if bias:  # the reference there is near the independent odometry's: the error is the firmware's
        own = _own_errors(live, DRIVE, range(WRONG_FRAME, WRONG_FRAME + 1))
        assert max(max(e) for e in own) <= 0.5  # (LSB; the published error is 2.7 of them)
    bridge = RobotTelemetry("r", live.monitor.tracker.geometry, DRIVE.integrator,
                            counter_bits=DRIVE.robot.counter_bits, publish_hz=publish_hz)
    published = [p for msg in _messages(tmp_path / "drive.log") for p in bridge.feed(msg)]
    errors = [json.loads(dumps(p)) for leaf, p in published if leaf == "error"]
    return errors, live.frames.index(WRONG_FRAME)


@pytest.mark.parametrize("publish_hz", [10.0, 1_000.0])
def test_the_wrong_sample_of_a_held_batch_is_published(tmp_path: Path, publish_hz: float) -> None:
    errors, seq = _errors(tmp_path, True, publish_hz)
    assert not any(e["enc_seq"] == seq for e in errors)  # never the published sample itself
    carried = [e for e in errors
               if "since_last" in e and e["since_last"]["worst"]["enc_seq"] == seq]
    assert len(carried) == 1  # absent before
    since = carried[0]["since_last"]
    assert since["samples"] > 40  # the batch released at once (and the rate's skipped ones)
    assert since["wrong"] >= 1
    assert since["worst"]["pose_vs_reference"]["dpos_m"] > 2e-4  # 2.7 LSB
    assert since["worst"]["allowance_m"] == 0.0
    assert carried[0]["pose_wrong"] is False  # its last sample right: hidden before


def test_a_correct_drive_publishes_no_since_last(tmp_path: Path) -> None:
    """The guard: nothing added to a right drive's ``error`` (passes before the change too)."""
    errors, _ = _errors(tmp_path, False, 1_000.0)
    assert len(errors) > 200
    assert not any("since_last" in e for e in errors)
