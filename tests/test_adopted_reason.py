"""An OK after the live reference adopted the firmware's own pose says so (issue #11: the verdict
is the product; ``host.judge.liveadopted``).

After a config change the firmware applied, or a reboot the judge was told late (its boot
summaries lost until UPTIME 1 s), the live reference restarts at the next on-board pose: that
pose is not checked independently. The monitor's OK said nothing of it (an unseen restart's new
start, a placement after a gap were said); now its ``why`` says it, and the bridge's status
carries ``reference_adopted``, until the pose is set anew whole (a reboot told at power-up).
The drives are right by the tests' own float64 (``test_monitor_config._dead_reckoned``,
``test_analysis_reboot.independent``: cantools and float64, not the judges under test).
"""

from __future__ import annotations

from pathlib import Path

import can

from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.host.protocol.commands import CommandEncoder
from odocan.sim.robot import load
from tests.test_analysis_reboot import REBOOT, independent, rebooting_drive
from tests.test_live_reboot import bridge_of, monitor_of
from tests.test_monitor_config import KOBUKI, WIDER, _Bus, _drive


def _adopted_why(why: list[str]) -> list[str]:
    return [line for line in why if "restarted at the firmware's own pose" in line]


def test_an_ok_after_a_config_change_says_the_reference_adopted_the_pose() -> None:
    bus, encoder = _Bus(), CommandEncoder()
    bridge = RobotTelemetry("r1", Geometry.of(KOBUKI), "exact", counter_bits=KOBUKI.counter_bits)
    heard = bus._heard

    def both(can_id: int, data: bytes) -> None:  # the bridge hears every frame the monitor does
        heard(can_id, data)
        bridge.feed(can.Message(timestamp=bus.t_s, arbitration_id=can_id, is_extended_id=False,
                                data=data))

    bus._heard = both  # type: ignore[method-assign]
    for _ in range(100):
        bus.period()
    health = bus.monitor.health(now_s=bus.t_s)
    assert health["state"] == "OK"
    assert not _adopted_why(health["why"])
    assert "reference_adopted" not in bridge.status()[1]
    _drive(bus, encoder, WIDER, 299)
    assert set(bus.acks[-7:]) == {0}  # applied (the pose right: test_monitor_config)
    health = bus.monitor.health(now_s=bus.t_s)
    assert health["state"] == "OK", health["why"]
    said = _adopted_why(health["why"])
    assert len(said) == 1, health["why"]
    assert "after a config change" in said[0]
    adopted = bridge.status()[1]["reference_adopted"]
    assert [a["cause"] for a in adopted] == ["a config change"]
    seq = bus.monitor.tracker.adopted.life[0].enc_seq
    assert adopted[0]["enc_seq"] == seq
    assert 100 <= seq < 110  # the first pose from the APPLY on


def test_an_ok_after_a_reboot_told_late_says_the_reference_adopted_the_pose(
    tmp_path: Path,
) -> None:
    profile = load("kobuki")
    synth = rebooting_drive(profile, "exact")
    for k in range(REBOOT, REBOOT + 110):  # every summary of its first 1.1 s lost
        synth.groups[k] = [line for line in synth.groups[k] if " 380#" not in line.upper()]
    path = synth.write(tmp_path / "late_reboot.log")
    assert independent(path, profile, "exact", REBOOT)  # a correct firmware
    monitor, bridge = monitor_of(path, "kobuki", "exact"), bridge_of(path, "kobuki", "exact")
    assert [e["kind"] for e in monitor.events] == ["reboot"]
    assert "-> 1 s" in monitor.events[0]["detail"], monitor.events  # told late
    health = monitor.health(now_s=monitor.tracker.now_s)
    assert health["state"] == "OK", health["why"]
    said = _adopted_why(health["why"])
    assert len(said) == 1, health["why"]
    assert "after a reboot told late" in said[0]
    adopted = bridge.status()[1]["reference_adopted"]
    assert [a["cause"] for a in adopted] == [
        "a reboot told late (its boot summary said UPTIME 1 s)"]


def test_a_reboot_told_at_power_up_adopts_nothing(tmp_path: Path) -> None:
    """The control: the reboot told by its first summary (UPTIME 0) starts at (0, 0, 0)."""
    path = rebooting_drive(load("kobuki"), "exact").write(tmp_path / "reboot.log")
    monitor, bridge = monitor_of(path, "kobuki", "exact"), bridge_of(path, "kobuki", "exact")
    health = monitor.health(now_s=monitor.tracker.now_s)
    assert health["state"] == "OK", health["why"]
    assert not _adopted_why(health["why"])
    assert "reference_adopted" not in bridge.status()[1]


def test_a_watch_begun_mid_drive_names_no_integrator_change(tmp_path: Path) -> None:
    """``odocan monitor`` started 1 s into a drive (no ``--integrator``) said its OK came
    "after an integrator change (None -> exact)": the firmware changed nothing, the watch only
    heard the integrator for the first time after its first poses. The adoption is real (the
    pose there is the firmware's own) and is said, with its true cause."""
    from odocan.host.cli.app import main
    from odocan.host.judge.monitor import BusMonitor

    path = tmp_path / "drive.log"
    assert main(["run", "--robot", "kobuki", "--duration", "2", "--log", str(path)]) == 0
    monitor = BusMonitor(load("kobuki"), None)
    with can.LogReader(str(path)) as reader:
        for msg in reader:
            if msg.timestamp >= 1.0:  # the watch begins mid-drive
                monitor.feed(msg, now_s=msg.timestamp)
    health = monitor.health(now_s=monitor.tracker.now_s)
    assert health["state"] == "OK", health["why"]
    said = _adopted_why(health["why"])
    assert len(said) == 1, health["why"]
    assert "integrator change" not in said[0]
    assert "after the integrator (exact) was first heard after the watch's first poses" in said[0]
