"""Outside trial 38 (issue #11 item 5): ``odocan sim``, ``odocan firmware``, ``odocan monitor``
and ``odocan bridge`` as processes on udp_multicast, the firmware killed and restarted.

Found: after ``kill -9`` of the firmware the bridge kept publishing a retained ``status`` whose
firmware summary said OK, with no age; ``odocan monitor --mqtt --json`` 6 s after the kill showed
the robot ``"state": "OK"``, ``stale`` false (its row's age is the bridge's last message, which
stays fresh). Now the status carries ``firmware_heard`` (``host.mqtt.firmwareheard``) and the
fleet view shows STALE. Pinned passes: ``monitor --json`` says STALE with the firmware's age
within a second of the kill; a restarted firmware is a ``reboot`` event, the reference restarts
and the pose is judged right against it.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import can
import pytest

from odocan.firmware import frames as fr
from odocan.host.cli.app import main
from odocan.host.mqtt.firmwareheard import firmware_heard
from odocan.host.mqtt.fleetview import RobotState, fleet_snapshot
from tests.conftest_mqtt import Mosquitto
from tests.conftest_mqtt import mosquitto as mosquitto  # the fixtures
from tests.conftest_mqtt import restore_logging as restore_logging
from tests.fleet_watch_until import BOUND_S as FLEET_BOUND_S
from tests.fleet_watch_until import end_watch_once
from tests.test_realtime import _open_udp_or_skip, _udp_channel

ROOT = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "odocan"]
BOUND_S = 60.0  # every wait below ends when what it waits for is seen; this is its bound


def test_firmware_heard_age_and_unknown_clock() -> None:
    fresh = firmware_heard([100.0, 100.05], 0.2, 100.1)
    assert fresh is not None
    assert fresh["stale"] is False
    assert fresh["age_s"] == 0.05
    silent = firmware_heard([100.0, None], 0.2, 103.0)
    assert silent is not None
    assert silent["stale"] is True
    assert silent["age_s"] == 3.0
    assert firmware_heard([None, None], 0.2, 103.0) is None
    lockstep = firmware_heard([12.5], 0.2, 1.8e9)  # bus time from 0: no wall-clock age
    assert lockstep is not None
    assert lockstep["age_s"] is None
    assert lockstep["stale"] is None


def _status(heard: dict[str, Any] | None) -> dict[str, Any]:
    summary = {"state": "OK", "integrator": "EXACT", "reason": "NONE", "error_mask": 0,
               "uptime": 5}
    status: dict[str, Any] = {"state": "online", "firmware": {"summary": summary}}
    if heard is not None:
        status["firmware_heard"] = heard
    return status


def test_fleet_row_of_a_silent_firmware_is_stale_not_ok() -> None:
    silent = {"node": "ODOM_MCU", "age_s": 2.8, "timeout_s": 0.2, "stale": True}
    row = fleet_snapshot({"r": RobotState("r", status=_status(silent))})["r"]["status"]
    assert row["state"] == "STALE"
    assert row["reported_state"] == "OK"
    assert row["firmware_age_s"] == 2.8
    fresh = {"node": "ODOM_MCU", "age_s": 0.01, "timeout_s": 0.2, "stale": False}
    assert fleet_snapshot({"r": RobotState("r", status=_status(fresh))})["r"]["status"][
        "state"] == "OK"
    # a status of a bridge before firmware_heard: as before
    assert fleet_snapshot({"r": RobotState("r", status=_status(None))})["r"]["status"][
        "state"] == "OK"


# --- processes ------------------------------------------------------------------------------


class _Rig:
    """Processes on one fresh udp_multicast channel and a listener of it."""

    def __init__(self, tmp: Path) -> None:
        self.argv, kwargs = _udp_channel()
        self.listener = _open_udp_or_skip(kwargs)
        self.tmp, self.procs, self.frames = tmp, list[subprocess.Popen[str]](), list[
            can.Message]()

    def start(self, *args: str, bus: bool = True) -> subprocess.Popen[str]:
        proc = subprocess.Popen([*CLI, *args, *(self.argv if bus else [])], cwd=ROOT,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.procs.append(proc)
        return proc

    def listen_until(self, until: Callable[[], bool], what: str) -> None:
        end = time.monotonic() + BOUND_S
        while not until():
            if time.monotonic() > end:
                pytest.fail(f"not seen within {BOUND_S} s: {what}")
            msg = self.listener.recv(0.02)
            if msg is not None:
                self.frames.append(msg)

    def poses_since(self, k: int) -> int:
        return sum(1 for m in self.frames[k:] if m.arbitration_id == fr.ODOM_POSE_X_ID)

    def close(self) -> None:
        for proc in self.procs:
            if proc.poll() is None:
                proc.kill()
            proc.communicate()
        self.listener.shutdown()


@pytest.fixture
def rig(tmp_path: Path) -> Iterator[_Rig]:
    out = _Rig(tmp_path)
    try:
        yield out
    finally:
        out.close()


def _logged_poses(log: Path) -> int:
    """ODOM_POSE_X frames the monitor recorded so far (its ``--log``, candump lines)."""
    try:
        text = log.read_text()
    except FileNotFoundError:
        return 0
    return sum(1 for line in text.splitlines()[:-1] if f" {fr.ODOM_POSE_X_ID:03X}#" in line)


def _json_of(proc: subprocess.Popen[str]) -> dict[str, Any]:
    """SIGINT, then the JSON it printed."""
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    assert "Traceback" not in err, err
    data: dict[str, Any] = json.loads(out)
    return data


def _statuses(broker: Mosquitto) -> tuple[Any, list[dict[str, Any]]]:
    import paho.mqtt.client as mqtt
    from paho.mqtt.enums import CallbackAPIVersion

    seen: list[dict[str, Any]] = []
    client = mqtt.Client(CallbackAPIVersion.VERSION2)
    url = broker.url()
    client.username_pw_set(url.username, url.password)
    client.on_message = lambda _c, _u, m: seen.append(json.loads(m.payload)) if m.topic.endswith(
        "/status") else None
    client.connect(url.host, url.port)
    client.subscribe("odocan/robot001/status", qos=1)
    client.loop_start()
    return client, seen


def test_killed_firmware_is_stale_on_monitor_bridge_and_fleet_view(
        rig: _Rig, mosquitto: Mosquitto, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str], restore_logging: None) -> None:
    client, statuses = _statuses(mosquitto)
    url = mosquitto.url()
    broker = f"mqtt://{url.username}:{url.password}@{url.host}:{url.port}"
    firmware = rig.start("firmware", "--firmware", "python")
    rig.start("sim", "--scenario", "random", "--seed", "5", "--duration", "120")
    monitor = rig.start("monitor", "--json", "--duration", "120", "--log", str(rig.tmp / "w.log"))
    rig.start("bridge", "--broker", broker, "--duration", "120")
    rig.listen_until(lambda: rig.poses_since(0) > 100, "100 poses")
    rig.listen_until(lambda: _logged_poses(rig.tmp / "w.log") > 20, "the monitor hearing poses")
    rig.listen_until(lambda: any((s.get("firmware_heard") or {}).get("stale") is False
                                 for s in statuses), "a bridge status with the firmware fresh")
    firmware.send_signal(signal.SIGKILL)
    firmware.wait()
    killed = time.monotonic()
    k = len(statuses)
    rig.listen_until(lambda: any((s.get("firmware_heard") or {}).get("stale") is True
                                 for s in statuses[k:]), "a bridge status with the firmware stale")
    heard = next(s["firmware_heard"] for s in statuses[k:] if s["firmware_heard"]["stale"])
    assert heard["timeout_s"] == pytest.approx(0.2)
    assert heard["age_s"] > heard["timeout_s"]
    assert heard["age_s"] <= time.monotonic() - killed + 0.5  # an age, not a guess
    # the fleet view (in-process: it ends once it holds a status of the silence, BOUND_S a bound)
    end_watch_once(monkeypatch, lambda w: "robot001" in w.table and (
        w.table["robot001"].status.get("firmware_heard") or {}).get("stale") is True)
    capsys.readouterr()
    assert main(["monitor", "--broker", broker, "--json", "--duration", FLEET_BOUND_S]) == 0
    row = json.loads(capsys.readouterr().out)["robots"]["robot001"]
    assert row["status"]["state"] == "STALE", row  # was "OK" 6 s after the kill
    assert row["status"]["reported_state"] == "OK"
    assert row["status"]["firmware_age_s"] > 0.2
    watch = _json_of(monitor)
    assert watch["health"]["state"] == "STALE", watch["health"]
    node = watch["health"]["nodes"]["ODOM_MCU"]
    assert node["stale"]
    assert node["age_s"] > node["timeout_s"] == pytest.approx(0.2)
    assert "silent for" in watch["health"]["why"][0]
    client.loop_stop()
    client.disconnect()


def test_restarted_firmware_is_a_reboot_event_and_judged_right(rig: _Rig) -> None:
    firmware = rig.start("firmware", "--firmware", "python")
    rig.start("sim", "--scenario", "random", "--seed", "5", "--duration", "120")
    # the monitor started in the first firmware's INIT second: its first pose near the 0.8 s
    # summary (COUNTER 0, UPTIME 0) was told a reboot (``host.judge.initfirst``; made
    # deterministic in tests/test_init_first_pose.py)
    monitor = rig.start("monitor", "--json", "--duration", "120", "--log", str(rig.tmp / "w.log"))
    rig.listen_until(lambda: _logged_poses(rig.tmp / "w.log") > 100, "the monitor hearing poses")
    firmware.send_signal(signal.SIGKILL)
    firmware.wait()
    k = len(rig.frames)
    rig.listen_until(lambda: len(rig.frames) > k + 100, "the sim's frames after the kill")
    k = len(rig.frames)
    rig.start("firmware", "--firmware", "python")
    rig.listen_until(lambda: rig.poses_since(k) > 150, "150 poses of the new firmware")
    watch = _json_of(monitor)
    reboots = [e for e in watch["health"]["events"] if e["kind"] == "reboot"]
    assert len(reboots) == 1, watch["health"]["events"]
    assert "reference restarted" in reboots[0]["detail"]
    assert watch["reference"]["starts"] == 2
    health = watch["health"]
    # on a loaded machine the new process may tick first with its mailbox full (it opened the
    # bus ~0.7 s before): it says so itself, DEGRADED POSE_UNCERTAIN, and is never POSE WRONG
    # for it (was, 4 runs in 10: tests/test_reboot_halted_first_tick.py)
    assert health["state"] in ("OK", "DEGRADED"), health
    assert all(why.startswith("firmware reports DEGRADED") for why in health["why"]), health
    error = watch["error"]["pose_vs_reference"]
    assert error["max_dpos_beyond_allowance_m"] < 1e-4  # was 7.87 m before #11
    assert watch["health"]["pose_wrongs"]["episodes"] == 0


def _stop_when(proc: subprocess.Popen[str], state: str) -> None:
    """SIGSTOP ``proc`` once its ``/proc`` state is ``state`` ("S": asleep, between two ticks;
    a machine without ``/proc``: at once)."""
    stat = Path(f"/proc/{proc.pid}/stat")
    end = time.monotonic() + BOUND_S
    while stat.exists() and stat.read_text().rsplit(")", 1)[1].split()[0] != state:
        if time.monotonic() > end:
            pytest.fail(f"the firmware never in state {state} within {BOUND_S} s")
    proc.send_signal(signal.SIGSTOP)


def _stopped_2_s(rig: _Rig, state: str) -> tuple[subprocess.Popen[str], dict[str, Any]]:
    """The firmware SIGSTOPped 2 s (in ``state``: ``_stop_when``) and SIGCONTed under the
    monitor: the firmware's process and the monitor's JSON after 100 more poses."""
    firmware = rig.start("firmware", "--firmware", "python")
    rig.start("sim", "--scenario", "random", "--seed", "7", "--duration", "120")
    log = rig.tmp / "w.log"
    monitor = rig.start("monitor", "--json", "--duration", "120", "--log", str(log))
    rig.listen_until(lambda: _logged_poses(log) > 100, "the monitor hearing poses")
    _stop_when(firmware, state)
    time.sleep(2.0)  # the fault itself: a firmware halted 2 s
    firmware.send_signal(signal.SIGCONT)
    after = _logged_poses(log)
    rig.listen_until(lambda: _logged_poses(log) > after + 100, "100 poses after SIGCONT")
    return firmware, _json_of(monitor)


def test_firmware_stopped_2_s_ends_degraded_with_a_reason_and_its_pose_judged(rig: _Rig) -> None:
    """SIGSTOP 2 s between two ticks, SIGCONT (issue #11: before, 398 releases skipped, 220
    mailbox overflows, state OK, the pose 0.43 m off for good): the firmware says DEGRADED with
    a reason, the monitor shows it, one firmware, and finds no pose wrong against the reference
    (trial38: 8.5-9.9 mm vs the truth after, Python and C, with POSE_UNCERTAIN saying the pose
    may be off). Stopped asleep, between ticks: a stop that lands mid-tick (a loaded host's,
    now and then) sends the rest of the tick after the halt; its summary the halt's length late
    was CONFLICT "two senders of ODOM_STATUS interleave" in the full run (fixed:
    ``host.judge.haltedsend``), its late ODOM_POSE_Y is still POSE WRONG live (16.5 and 11.2 mm
    in the two of three stops sent while it ran that split a tick after its ODOM_POSE_X): both
    made by hand in ``tests/test_halted_send.py``."""
    firmware, watch = _stopped_2_s(rig, "S")
    assert watch["status"]["state"] == "DEGRADED", watch["status"]
    assert watch["status"]["reason"] in ("TIME_LOST", "POSE_UNCERTAIN", "MAILBOX_OVERFLOW")
    assert "TIME_LOST" in watch["status"]["latched_errors"]
    kinds = [e["kind"] for e in watch["health"]["events"]]
    assert "two sources" not in kinds, watch["health"]["events"]
    assert watch["health"]["state"] == "DEGRADED", watch["health"]
    assert "firmware reports DEGRADED" in watch["health"]["why"][-1]
    assert watch["health"]["pose_wrongs"]["episodes"] == 0
    assert watch["error"]["pose_vs_reference"]["max_dpos_beyond_allowance_m"] < 1e-4
    assert firmware.poll() is None  # it runs on
