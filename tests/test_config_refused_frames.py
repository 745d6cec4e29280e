"""A config the firmware ACKs and then refuses every encoder frame under (found by trial 22, F2).

On a lockstep drive of a robot with 32-bit counters the user configures 16-bit counters (a
mistake: the wire carries 24 bits and the drive's counts set the top 8): our firmware ACKs it,
then refuses every WHEEL_ENCODERS frame (DEGRADED, IMPLAUSIBLE_STEP) and holds its pose and
ODOM_TWIST on the last frame it integrated (the DBC: "after integrating encoder frame
ENC_COUNTER"). Before, the live judges (monitor, bridge) named the held twist 16, 32, ...
frames ahead once the hold outlived their 5 s window and FAILed the correct firmware ("ODOM_TWIST
outside the reference's speeds by up to 172 mm/s"), while ``analyze`` PASSed it having dropped
the 10 s after the config without a word (its frames in no E2E category, its config event
gone). An independent check written here says the firmware is right; both judges must agree:
PASS, the stretch after the config named as not judged.
"""

from __future__ import annotations

import json
import uuid
from pathlib import Path
from typing import cast

import can
import pytest
from cantools.database.can import Database

from odocan.host.cli.app import main
from odocan.host.judge.monitor import BusMonitor
from odocan.host.protocol.heard import Recorder
from odocan.host.protocol.session import CommandSession
from odocan.sim import robot
from odocan.sim.contract import database
from odocan.sim.rig import LockstepRig, RigConfig
from tests import independent_checker as checker
from tests.test_analyze_config import parse_candump_messages

TOML = """name = "odd32"
counts_per_rev = 4096
wheel_radius_left_m = 0.0613
wheel_radius_right_m = 0.0617
wheelbase_m = 0.4871
counter_bits = 32
max_wheel_speed_m_s = 1.5
"""
APPLY_S = 3.0  # when the config is sent
AFTER_S = 10.0  # how long the drive goes on after it
SEED = 2  # a drive whose left wheel runs backwards from before the config to the end


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The drive's candump log and the robot's TOML."""
    folder = tmp_path_factory.mktemp("refused")
    toml = folder / "odd32.toml"
    toml.write_text(TOML)
    odd = robot.load(str(toml))
    messages: list[can.Message] = []

    class Keep(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            messages.append(msg)

    heard = Recorder(database())
    rig = LockstepRig(RigConfig(robot=odd, seed=SEED, channel=f"t-{uuid.uuid4().hex}",
                                duration_s=60.0), [heard, Keep()])
    try:
        session = CommandSession(heard, rig.send, rig.run_until, ack_timeout_s=0.5)
        rig.run(APPLY_S)
        assert session.configure(
            counts_per_rev=odd.counts_per_rev, wheel_radius_left_m=odd.wheel_radius_left_m,
            wheel_radius_right_m=odd.wheel_radius_right_m, wheelbase_m=odd.wheelbase_m,
            counter_bits=16, integrator="euler")["RESULT"] == "ACK"
        rig.run(AFTER_S)
    finally:
        rig.close()
    log = folder / "refused.log"
    log.write_text("".join(f"({m.timestamp:.6f}) vcan0 {m.arbitration_id:03X}#"
                           f"{bytes(m.data).hex().upper()}\n" for m in messages))
    return log, toml


def _raw(db: Database, m: can.Message) -> dict[str, float]:
    """The frame's raw signals (cantools)."""
    return cast(dict[str, float], db.decode_message(m.arbitration_id, bytes(m.data),
                                                    decode_choices=False))


def _split(log: Path) -> tuple[list[can.Message], list[can.Message]]:
    """The frames before the ODOM_CONFIG APPLY (PARAM 15) and those after its ODOM_ACK."""
    db = database()
    messages = list(parse_candump_messages(log))
    apply_at = next(k for k, m in enumerate(messages) if m.arbitration_id == 0x301
                    and _raw(db, m)["PARAM"]
                    == 15)
    acked = next(k for k, m in enumerate(messages) if k > apply_at and m.arbitration_id == 0x302)
    return messages[:apply_at], messages[acked + 1:]


def test_the_independent_check_says_the_firmware_is_right(drive: tuple[Path, Path],
                                                          tmp_path: Path) -> None:
    """Before the APPLY its pose follows the counts; after it every frame sets a count bit a
    16-bit counter has not (refused), and the pose and twist frames repeat the last ones before
    it, naming the last encoder frame before it, their speed that of the step into it."""
    log, _ = drive
    before, after = _split(log)
    head = tmp_path / "head.log"
    head.write_text("".join(f"({m.timestamp:.6f}) vcan0 {m.arbitration_id:03X}#"
                            f"{bytes(m.data).hex().upper()}\n" for m in before))
    verdict = checker.check(head, checker.Robot(4096, 61_300_000, 61_700_000, 487_100_000, 32,
                                                1500), "exact", lambda _t: (0.0, 0.0, 0.0))
    assert verdict.passed, verdict
    assert verdict.samples > 100
    db = database()
    counts = [_raw(db, m) for m in after if m.arbitration_id == 0x100]
    assert len(counts) > 900
    assert all(max(c["LEFT_COUNT"], c["RIGHT_COUNT"]) >= 1 << 16 for c in counts)
    named = [_raw(db, m) for m in before if m.arbitration_id == 0x100]
    for can_id in (0x200, 0x201, 0x202):  # the same values naming the same frame throughout
        held = {bytes(m.data)[1:] for m in after if m.arbitration_id == can_id}
        assert len({(b[0] & 0xF0, b[1:]) for b in held}) == 1  # (its own COUNTER aside)
        assert next(iter(held))[0] >> 4 == named[-1]["COUNTER"]  # the last before the APPLY
    twist = _raw(db, next(m for m in after if m.arbitration_id == 0x202))
    at = len(named) - 1
    per_count = [2 * 3.141592653589793 * r / 4096 for r in (0.0613, 0.0617)]
    d = [((named[at][w] - named[at - 1][w] + (1 << 23)) % (1 << 24)) - (1 << 23)
         for w in ("LEFT_COUNT", "RIGHT_COUNT")]
    speed_mps = (d[0] * per_count[0] + d[1] * per_count[1]) / 2 / 0.01
    assert abs(twist["LINEAR_VEL"]) > 0.05  # a moving robot: a misnamed frame shows
    assert twist["LINEAR_VEL"] == pytest.approx(speed_mps, abs=0.0015)


def test_analyze_counts_and_names_the_stretch_after_the_config(
        drive: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log, toml = drive
    report = tmp_path / "report.json"
    assert main(["analyze", str(log), "--robot", str(toml), "--report", str(report)]) == 0
    out = capsys.readouterr().out
    said = json.loads(report.read_text())
    frames = said["frames"]["WHEEL_ENCODERS"]
    assert said["e2e"]["WHEEL_ENCODERS"]["ok"] == frames  # every frame in a category
    assert said["e2e"]["ODOM_ACK"]["ok"] == said["frames"]["ODOM_ACK"]
    configs = [e for e in said["events"] if e["kind"] == "config"]
    assert [e["parameters"]["COUNTER_BITS"] for e in configs] == [16.0]
    unjudged = [e for e in said["events"] if e["kind"] == "unjudged"]
    assert len(unjudged) == 1
    assert unjudged[0]["seconds"] > AFTER_S - 0.1
    assert "IMPLAUSIBLE_STEP" in unjudged[0]["detail"]
    assert "not judged" in out.split("PASS: ", 1)[1]


def test_the_monitor_agrees(drive: tuple[Path, Path]) -> None:
    """The live judges (the monitor's; the bridge's telemetry names twists the same way) fed
    the same frames: the held twist judged against the frame it names, no FAIL."""
    log, toml = drive
    monitor = BusMonitor(robot.load(str(toml)))
    for msg in parse_candump_messages(log):
        monitor.feed(msg, now_s=msg.timestamp)
    health = monitor.health(now_s=msg.timestamp)
    assert not any("ODOM_TWIST" in why for why in health["why"]), health["why"]
    assert health["pose_wrongs"]["episodes"] == 0
    assert health["state"] != "TWIST WRONG"
