"""``odocan monitor``: the live model on a real-time bus, its JSON, the screen, bad input, MQTT.

The source is the lockstep rig's set of nodes stepped every 10 ms of the wall clock in a thread
of the test process, every frame it makes forwarded to a python-can ``virtual`` channel that the
monitor listens to, with garbage frames mixed in. The source starts once the monitor's bus is
open and sends a known number of ticks, so every count is exact; rates are checked loosely.
The frames keep the rig's simulated times (the monitor pairs poses by bus time: the wall clock's
gaps on a loaded machine split pairs), and the monitor ends (as on ``q``) ``LINGER_S`` after it
heard the source's last frame, not at a wall-clock ``--duration`` (only a bound here): on a loaded
machine the source's second took longer than the monitor's two, and the counts came out short
(the tests passed alone and failed under load).
"""

from __future__ import annotations

import asyncio
import itertools
import json
import os
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import can
import pytest

from odocan.host.cli.app import build_parser, main
from odocan.host.cli.subparsers import monitor as monitor_cmd
from odocan.host.io.buses import open_bus
from odocan.host.judge.monitor import error_names
from odocan.host.mqtt.broker import BrokerURL
from odocan.host.report.tui_app import MonitorApp
from odocan.sim import robot
from odocan.sim.rig import LockstepRig, RigConfig
from tests.fleet_run_until import pace_never_late
from tests.test_cli_run import assert_usage_error, run_cli

TICKS = 100  # 1 s of real time
LINGER_S = 1.0  # the monitor listens on this long after the source's last frame (staleness)
BOUND = "60"  # the monitor's --duration: a bound only (it ends once the drive was heard)
GARBAGE_EVERY = 25  # ticks: one of each garbage kind
_channels = itertools.count()


@dataclass
class Source:
    """A rig paced to the wall clock on its own channel, forwarding every frame to ``channel``."""

    channel: str
    ticks: int = TICKS
    garbage: bool = True
    robot_name: str = "pmir"  # the rig's robot (its firmware's PROFILE page names it)
    injected: int = 0  # rounds of garbage sent
    done: threading.Event = field(default_factory=threading.Event)

    def run(self, start: threading.Event) -> None:
        """Wait for ``start`` (the monitor's bus is open), then send ``ticks`` ticks."""
        # the rig's own (simulated) times on the bus: the monitor pairs poses by bus time, and
        # the wall clock's gaps on a loaded machine split pairs (46 samples of 50 under load)
        out = can.Bus(interface="virtual", channel=self.channel, preserve_timestamps=True)
        config = RigConfig(robot=robot.load(self.robot_name), seed=2, channel=f"{self.channel}-rig")
        last_pose_y: list[can.Message] = []
        forward = _Forward(out, last_pose_y)
        try:
            with LockstepRig(config, listeners=[forward]) as rig:
                if not start.wait(20):
                    return
                t0 = time.monotonic()
                for k in range(self.ticks):
                    rig.step()
                    if self.garbage and k % GARBAGE_EVERY == GARBAGE_EVERY - 1:
                        self._send_garbage(out, last_pose_y[-1])
                    time.sleep(max(0.0, t0 + (k + 1) * 0.01 - time.monotonic()))
        finally:
            out.shutdown()
            self.done.set()

    def _send_garbage(self, out: can.BusABC, pose_y: can.Message) -> None:
        """An unknown ID, a WHEEL_ENCODERS of 4 bytes, a remote frame, an error frame and an
        ODOM_POSE_Y with one payload bit flipped (bad CRC)."""
        corrupted = bytearray(pose_y.data)
        corrupted[3] ^= 0x10
        t_s = pose_y.timestamp  # the bus time of the frames around them
        for msg in (
            can.Message(timestamp=t_s, arbitration_id=0x123, data=b"\x01\x02\x03",
                        is_extended_id=False),
            can.Message(timestamp=t_s, arbitration_id=0x100, data=b"\x00\x01\x02\x03",
                        is_extended_id=False),
            can.Message(timestamp=t_s, arbitration_id=0x300, is_remote_frame=True, dlc=8,
                        is_extended_id=False),
            can.Message(timestamp=t_s, is_error_frame=True),
            can.Message(timestamp=t_s, arbitration_id=0x201, data=bytes(corrupted),
                        is_extended_id=False),
        ):
            out.send(msg)
        self.injected += 1


class _Forward(can.Listener):
    """Send every frame of the rig's host bus to ``out`` (keeping the last ODOM_POSE_Y)."""

    def __init__(self, out: can.BusABC, last_pose_y: list[can.Message]) -> None:
        self.out, self.last_pose_y = out, last_pose_y

    def on_message_received(self, msg: can.Message) -> None:
        if msg.arbitration_id == 0x201:
            self.last_pose_y[:] = [msg]
        self.out.send(msg)


class _Heard:
    """The monitor's bus, which ends the monitor's receive loop (``quit``, as ``q`` does) once
    the source is done, its every frame received, and ``LINGER_S`` passed without a frame."""

    def __init__(self, bus: can.BusABC, src: Source, app: MonitorApp) -> None:
        self.bus, self.src, self.app = bus, src, app
        self.quiet_since: float | None = None

    def recv(self, timeout: float | None = None) -> can.Message | None:
        msg = self.bus.recv(timeout)
        if msg is not None or not self.src.done.is_set():
            self.quiet_since = None
        elif self.quiet_since is None:
            self.quiet_since = time.monotonic()
        elif time.monotonic() - self.quiet_since >= LINGER_S:
            self.app.quit = True
        return msg


@pytest.fixture
def source(monkeypatch: pytest.MonkeyPatch) -> Iterator[Source]:
    """A Source on a fresh channel that starts when ``odocan monitor`` opens its bus; the
    monitor ends ``LINGER_S`` after it heard the whole drive (``_Heard``)."""
    yield from sources(monkeypatch)


def sources(monkeypatch: pytest.MonkeyPatch, **fields: Any) -> Iterator[Source]:
    """``source`` with its ``fields`` (its robot, ticks: read before ``odocan monitor`` runs)."""
    build_parser()  # every subcommand imported before the clock starts
    src = Source(f"odocan-test-monitor-{os.getpid()}-{next(_channels)}", **fields)
    opened = threading.Event()

    def open_and_start(args: Any, **overrides: Any) -> can.BusABC:
        bus = open_bus(args, **overrides)
        opened.set()
        return bus

    class UntilHeard(MonitorApp):
        def __init__(self, bus: can.BusABC, *args: Any, **kwargs: Any) -> None:
            super().__init__(_Heard(bus, src, self), *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(monitor_cmd, "open_bus", open_and_start)
    monkeypatch.setattr(monitor_cmd, "MonitorApp", UntilHeard)
    thread = threading.Thread(target=src.run, args=(opened,), name="source")
    thread.start()
    yield src
    opened.set()
    thread.join(30)


def monitor_json(capsys: pytest.CaptureFixture[str], *argv: str) -> dict[str, Any]:
    code, out, err = run_cli(capsys, "monitor", *argv, "--json")
    assert code == 0, err
    passed = err.startswith("monitor: PASS: the on-board pose right in ") and err.count("\n") == 1
    assert err == "" or passed, err  # a bus watch's one verdict line (a fleet's: none)
    result: dict[str, Any] = json.loads(out)
    return result


def test_monitor_json_on_a_live_bus(source: Source, capsys: pytest.CaptureFixture[str]) -> None:
    model = monitor_json(capsys, "-i", "virtual", "-c", source.channel, "--duration", BOUND)
    assert source.done.is_set()  # the whole drive was heard
    rounds = source.injected
    assert rounds == TICKS // GARBAGE_EVERY
    messages = model["messages"]
    enc = messages["WHEEL_ENCODERS"]
    assert enc["id"] == "0x100"
    assert enc["count"] == TICKS
    assert enc["e2e"] == {"ok": TICKS, "lost": 0, "repeated": 0, "crc_errors": 0,
                          "wrong_sequence": 0}
    assert set(enc["last"]) == {"CTRL_UPTIME", "LEFT_COUNT", "RIGHT_COUNT"}
    assert enc["units"] == {"CTRL_UPTIME": "s", "LEFT_COUNT": "count", "RIGHT_COUNT": "count"}
    pose_y = messages["ODOM_POSE_Y"]
    assert pose_y["count"] == TICKS // 2 + rounds
    assert pose_y["e2e"]["crc_errors"] == rounds
    assert pose_y["e2e"]["ok"] == TICKS // 2
    assert messages["ODOM_POSE_X"]["last"]["X"] == pytest.approx(model["pose"]["x_m"])
    assert model["unknown"] == {"unknown_id": rounds, "wrong_dlc": rounds,
                                "error_frames": rounds, "remote_frames": rounds,
                                "unprotected": 0, "ids": {"0x123": rounds}, "undecodable": 0}
    assert model["frames_total"] == sum(m["count"] for m in messages.values()) + 4 * rounds


def test_monitor_follows_the_firmware_and_its_pose(
    source: Source, capsys: pytest.CaptureFixture[str]
) -> None:
    model = monitor_json(capsys, "-i", "virtual", "-c", source.channel, "--duration", BOUND)
    status = model["status"]
    assert (status["state"], status["integrator"], status["error_mask"], status["errors"]) == (
        "OK", "EXACT", 0, [])
    assert status["uptime_s"] in (0, 1)
    assert model["reference"]["integrator"] == "exact"  # as ODOM_STATUS reports it
    assert model["reference"]["starts"] == 1
    vs_ref = model["error"]["pose_vs_reference"]
    assert vs_ref["samples"] >= TICKS // 2 - 35  # from the first pose after the first summary
    assert vs_ref["max_dpos_m"] < 2e-4  # quantisation of the start pose only
    assert vs_ref["max_dheading_rad"] < 2e-4
    vs_truth = model["error"]["pose_vs_truth"]
    assert vs_truth["samples"] >= 5
    assert vs_truth["max_dpos_m"] < 5e-3
    assert set(model["truth"]) == {"x_m", "y_m", "heading_rad", "heading_unwrapped_rad"}
    # the source stopped LINGER_S before the monitor: the firmware is stale, whatever it said
    health = model["health"]
    firmware = health["nodes"]["ODOM_MCU"]
    assert firmware["timeout_s"] == pytest.approx(0.2)  # 10 x ODOM_POSE_X's 20 ms
    assert firmware["stale"]
    assert firmware["age_s"] > 0.5
    assert health["state"] == "STALE"
    assert "ODOM_MCU silent for" in health["why"][0]
    assert health["events"] == []
    assert model["messages"]["ODOM_POSE_X"]["stale"]


def test_monitor_integrator_given(source: Source, capsys: pytest.CaptureFixture[str]) -> None:
    """With --integrator the reference starts at the first pose, whatever ODOM_STATUS says;
    another integrator than the firmware's still agrees to about the quantisation."""
    source.garbage = False
    model = monitor_json(capsys, "-i", "virtual", "-c", source.channel, "--duration", BOUND,
                         "--integrator", "rk2")
    assert model["reference"]["integrator"] == "rk2"
    assert model["error"]["pose_vs_reference"]["samples"] == TICKS // 2
    assert model["unknown"]["unknown_id"] == 0


def test_monitor_screen(source: Source, capsys: pytest.CaptureFixture[str]) -> None:
    """Without --json: the rich screen (its last frame, as stdout is not a terminal)."""
    code, out, err = run_cli(capsys, "monitor", "-i", "virtual", "-c", source.channel,
                             "--duration", BOUND)
    assert code == 0, err
    assert err.startswith("monitor: PASS: the on-board pose right in "), err
    assert f"odocan monitor virtual:{source.channel}" in out
    assert "firmware OK  reason no error bits" in out  # host.report.tui's screen, 80 columns
    assert "EXACT  uptime" in out
    assert "verdict STALE: ODOM_MCU silent for" in out  # the last frame: the source has stopped
    for name in ("WHEEL_ENCODERS", "ODOM_POSE_X", "SIM_TRUTH", "on-board ", "reference ",
                 "truth "):
        assert name in out
    assert f"not checked: unknown id {TICKS // GARBAGE_EVERY}" in out


class _InterruptingBus(can.BusABC):
    """A bus that hears a few frames and then gets Ctrl-C."""

    def __init__(self, frames: int) -> None:
        self.left = frames
        super().__init__(channel="interrupting")

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self.left == 0:
            raise KeyboardInterrupt
        self.left -= 1
        return can.Message(arbitration_id=0x7FF, data=b"\x00", timestamp=time.time()), False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        raise NotImplementedError


@pytest.mark.parametrize("json_mode", [True, False])
def test_monitor_ctrl_c_exits_cleanly(
    json_mode: bool, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(monitor_cmd, "open_bus", lambda args: _InterruptingBus(7))
    code, out, err = run_cli(capsys, "monitor", "-i", "virtual", *(["--json"] * json_mode))
    assert (code, err) == (0, "")
    if json_mode:
        model = json.loads(out)
        assert model["frames_total"] == 7
        assert model["unknown"]["ids"] == {"0x7FF": 7}
    else:
        assert "not checked: unknown id 7 (IDs 0x7FF×7)" in out


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["--duration", "0"], ["--duration"]),
        (["--duration", "nan"], ["--duration"]),
        (["-i", "nosuchinterface"], ["nosuchinterface"]),
        (["--integrator", "midpoint"], ["midpoint"]),
        (["--robot", "nosuchbot"], ["nosuchbot"]),
        (["--dbc", "/nonexistent/x.dbc"], ["/nonexistent/x.dbc"]),
        (["--mqtt", "http://example.org"], ["http://example.org"]),
        (["--mqtt", "mqtt://127.0.0.1:1", "-i", "virtual"], ["--broker", "-i"]),
    ],
)
def test_monitor_bad_input_is_one_line(
    argv: list[str], words: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert_usage_error(capsys, main(["monitor", *argv]), *words)


def test_monitor_mqtt_unreachable_broker(capsys: pytest.CaptureFixture[str]) -> None:
    from odocan.host.mqtt.broker import free_loopback_port

    url = f"mqtt://127.0.0.1:{free_loopback_port()}"
    code = main(["monitor", "--mqtt", url, "--duration", "0.5", "--json"])
    assert_usage_error(capsys, code, "cannot reach the MQTT broker", url)


@pytest.mark.parametrize("json_out", [True, False])
def test_monitor_without_a_duration_gives_up_on_a_broker_it_never_reached(
    capsys: pytest.CaptureFixture[str], json_out: bool
) -> None:
    """Before: it retried for ever, the screen saying "(reconnecting)", until stopped."""
    from odocan.host.mqtt.broker import free_loopback_port

    url = f"mqtt://127.0.0.1:{free_loopback_port()}"
    code = main(["monitor", "--broker", url, *(["--json"] if json_out else [])])
    if json_out:
        assert_usage_error(capsys, code, "cannot reach the MQTT broker", url, "for 5 s")
        return
    err = capsys.readouterr().err  # the screen drew the empty table meanwhile
    assert (code, err.count("\n"), err.startswith("error: cannot reach the MQTT broker")) == (
        2, 1, True), err


def test_monitor_mqtt_fleet_json(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Two real-time robots bridged to the embedded amqtt broker; the monitor's fleet table.
    The fleet on a clock never late (``PacedClock``): a tick 95 ms late (a loaded machine)
    halts the boards, and the firmwares' status then says DEGRADED (TIME_LOST), rightly."""
    pace_never_late(monkeypatch)
    from odocan.host.mqtt.broker import EmbeddedBroker
    from odocan.host.mqtt.fleetrun import FleetRun, run_fleet
    from odocan.sim.fleet import FleetConfig

    ready, reports = threading.Event(), []

    async def fleet() -> None:
        async with EmbeddedBroker() as broker:
            urls.append(str(broker.url))
            run = FleetRun(fleet=FleetConfig(robots=2, robot=robot.load("pmir"), seed=1),
                           duration_s=8.0, broker=broker.url, client_prefix="test-monitor")
            fleet_task = asyncio.create_task(run_fleet(run))
            await summaries_published(broker.url, {"robot001", "robot002"})
            ready.set()  # the monitor's 2 s start once each bridge has told its firmware's state
            reports.append(await fleet_task)

    urls: list[str] = []
    thread = threading.Thread(target=lambda: asyncio.run(fleet()), name="fleet")
    thread.start()
    assert ready.wait(30), "no firmware summary published"
    try:
        model = monitor_json(capsys, "--mqtt", urls[0], "--duration", "2")
    finally:
        thread.join(30)
    assert reports, "the fleet did not finish"
    assert model["broker"] == urls[0]
    robots = model["robots"]
    assert set(robots) == {"robot001", "robot002"}
    for row in robots.values():
        assert row["online"] is True
        assert set(row["pose"]) == {"x_m", "y_m", "heading_rad", "heading_unwrapped_rad"}
        assert row["error"]["dpos_m"] < 1e-3  # on-board vs float64: quantisation only
        assert row["status"]["state"] == "OK"
        # The bits are named as the mask says.
        assert row["status"]["errors"] == error_names(row["status"]["error_mask"])
        assert row["encoder_hz"] > 0
        assert row["stale"] is False  # the fleet was still publishing
        assert 0.0 <= row["age_s"] < 3.0


async def summaries_published(broker: BrokerURL, names: set[str]) -> None:
    """Return once every robot of ``names`` has a retained status with its firmware's summary
    (the bridge publishes one a second: on a loaded machine the first may come after 2 s), a
    pose and its error against the reference (under load: the status alone came first, then
    a 1.8 s stall, and the monitor's 2 s saw no error yet)."""
    from odocan.host.mqtt.fleetview import fleet_snapshot, fleet_states

    async for table in fleet_states(broker=broker, min_interval_s=0.0):
        rows = fleet_snapshot(table)
        if set(rows) >= names and all(None not in (rows[n]["status"], rows[n]["pose"],
                                                   rows[n]["error"]) for n in names):
            return


def test_error_names() -> None:
    from odocan.firmware.errors import ErrorFlag

    assert error_names(0) == []
    assert error_names(int(ErrorFlag.SATURATION | ErrorFlag.BUS_OFF)) == ["SATURATION", "BUS_OFF"]
    named = {int(flag) for flag in ErrorFlag}
    unnamed = next(bit for bit in range(16) if 1 << bit not in named)
    assert error_names(1 << unnamed | 1) == ["SATURATION", f"BIT{unnamed}"]


def test_rate_and_jitter_come_from_the_bus_timestamps() -> None:
    """The model's rate and jitter on a perfectly regular 100 Hz bus: exact, not a timing test
    (the frames carry their time; the live test above leaves rates to the wall clock)."""
    from odocan.firmware import frames as fw_frames
    from odocan.host.judge.monitor import BusMonitor
    from odocan.sim import frames as sf
    from odocan.sim.robot import load

    model = BusMonitor(load("pmir"))
    for k in range(200):
        data = sf.pack_wheel_encoders(k % 16, 5 * k, 5 * k)
        msg = can.Message(arbitration_id=fw_frames.WHEEL_ENCODERS_ID, data=data,
                          is_extended_id=False, timestamp=k * 0.01)
        model.feed(msg, now_s=k * 0.01)
    enc = model.snapshot(now_s=2.0)["messages"]["WHEEL_ENCODERS"]
    assert enc["rate_hz"] == pytest.approx(100.0, rel=1e-9)
    assert enc["jitter_ms"] == pytest.approx(0.0, abs=1e-6)


def test_a_watch_of_the_in_process_transport_that_hears_nothing_says_why(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """``monitor -i odocan`` in a process of its own hears no other process's frames: it said
    NO FIRMWARE and nothing more (a user's first try from a second terminal)."""
    code, out, err = run_cli(capsys, "monitor", "-i", "odocan", "-c",
                             f"odocan-alone-{os.getpid()}", "--duration", "0.3", "--json")
    assert code == 0, err
    assert json.loads(out)["health"]["state"] == "NO FIRMWARE"
    assert "the odocan interface carries frames within one process only" in err, err
