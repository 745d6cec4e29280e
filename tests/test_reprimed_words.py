"""An ambiguous silence is worded as what it is, by every judge alike (issue #11, point 5).

The live judges (the monitor's screen and ``--json``, the bridge's ``status`` events) told the
firmware's re-prime after a silence too long to read (kobuki: 391 periods and more) as "the
motor controller restarted (CTRL_UPTIME went back)": the controller had not restarted, its
CTRL_UPTIME never went back; the counts could not span the silence. The drive: the lockstep rig's
random drive with the motor controller muted 8 s (``tests.test_silence_gap``); the silence and
the controller's uptime are read from the log by cantools here, not by the judges.
"""

from __future__ import annotations

import itertools
import json
from pathlib import Path
from typing import Any

import pytest

from odocan.host.io.logs import parse_candump_line, read_log
from odocan.host.judge.analysis import analyze
from odocan.host.judge.livegapseen import end_of_watch
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.host.report.live import health_line
from odocan.sim.robot import load
from tests.dbc_typed import decode, number
from tests.test_silence_gap import ROBOT, _db, _silent_drive

WORDS = "re-primed: the counts could not span the silence"


@pytest.fixture(scope="module")
def silent(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The random drive, the motor controller muted 8 s from 6 s."""
    return _silent_drive(tmp_path_factory.mktemp("words"), "random", 4, 22.0, 6.0, 8.0)


def _premise(path: Path) -> None:
    """Cantools' reading: one silence of 800 periods or more, CTRL_UPTIME never going back."""
    db = _db()
    times, uptimes = [], []
    for line in path.read_text().splitlines():
        stamp, _, frame = line.split()[:3]
        head, payload = frame.split("#")
        if db.get_message_by_frame_id(int(head, 16)).name == "WHEEL_ENCODERS":
            s = decode(db, int(head, 16), bytes.fromhex(payload), decode_choices=False)
            times.append(float(stamp.strip("()")))
            uptimes.append(number(s["CTRL_UPTIME"]))
    assert max(b - a for a, b in itertools.pairwise(times)) > 7.9
    assert all(b >= a for a, b in itertools.pairwise(uptimes))


def _restarts(events: Any) -> list[str]:
    return [str(e["detail"]) for e in events if e["kind"] == "counter_restart"]


def test_every_judge_words_the_ambiguous_reset_as_a_re_prime(silent: Path) -> None:
    _premise(silent)
    profile = load(ROBOT)
    monitor = BusMonitor(profile)
    bridge = RobotTelemetry("r", Geometry.of(profile), "exact",
                            counter_bits=profile.counter_bits, publish_hz=10)
    last = 0.0
    for line in silent.read_bytes().splitlines(keepends=True):
        msg = parse_candump_line(line)
        if msg is not None:
            monitor.feed(msg, now_s=msg.timestamp)
            bridge.feed(msg)
            last = msg.timestamp
    for tracker in (monitor.tracker, bridge.tracker):
        end_of_watch(tracker)
    health = json.loads(json.dumps(monitor.health(now_s=last)))  # as ``monitor --json``
    status = json.loads(json.dumps(bridge.status()[1]))  # the bridge's status payload
    whole = analyze(read_log(silent), profile).report["events"]
    told = {"whole": _restarts(whole), "monitor": _restarts(health["events"]),
            "bridge": _restarts(status["events"])}
    for judge, details in told.items():
        assert len(details) == 1, (judge, details)
        assert details[0].startswith(WORDS), (judge, details)
        assert "CTRL_UPTIME went back" not in details[0], (judge, details)
    assert told["monitor"] == told["whole"] == told["bridge"]
    assert WORDS in health_line(health).plain  # the screen's verdict line
