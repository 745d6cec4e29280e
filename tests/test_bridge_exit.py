"""``odocan bridge``'s verdict at its end and its exit code (issue #11: the rig never shows OK
while the pose it reports is wrong; ``host.mqtt.endverdict``).

The bridge (its CLI, an embedded broker) hears a firmware's drive from a log: kobuki on an arc
whose X is 2 mm off from encoder frame 300 on, or the same drive right (``test_pose_wrongs``:
the firmware's integration checked against the independent float64 odometry, so the bias is the
only thing wrong). Its ``--duration`` comes once every frame was taken in. Before (main): the
retained ``status`` said POSE WRONG, the bridge printed no verdict and exited 0 both ways. Now
its last line is the robot's verdict and it exits 1 on the wrong pose, 0 on the right one; a
signal before ``--duration`` keeps 130 (its STOPPED line last, as before); ``--require-firmware``
fails a run that judged nothing. The retained ``offline`` status the bridge leaves on a real
broker (mosquitto) carries that same verdict (``watch_verdict``), for a dashboard that subscribes
after the bridge stopped (before: no verdict in it).
"""

from __future__ import annotations

import asyncio
import json
import os
import signal
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import can
import pytest

from odocan.host.cli.subparsers import bridge as bridge_cmd
from odocan.host.mqtt.broker import BrokerURL
from odocan.host.mqtt.busfeed import BusFeed
from odocan.host.mqtt.options import PASSWORD_ENV
from odocan.sim.robot import to_toml
from tests.conftest_mqtt import Mosquitto, client, mosquitto  # noqa: F401 (fixture)
from tests.test_cli_run import run_cli
from tests.test_distance import KOBUKI as DISTANCE_KOBUKI
from tests.test_distance import _synth, checker_errors_mm, checker_passes, off_by, short_drive
from tests.test_pose_wrongs import JUMP_AT, KOBUKI, _drive
from tests.test_stall_bound import _messages
from tests.test_watch_end import _profile_toml

WAIT_S = 60.0  # the bridge takes the drive's frames in (bounds a hung test, asserts nothing)
RETAINED_WAIT_S = 10.0  # the broker hands a new subscriber its retained status (bounds a hang)


class _ListBus(can.BusABC):
    """``frames``, then nothing (a ``recv`` waits its timeout, as a quiet bus's does)."""

    def __init__(self, frames: list[can.Message]) -> None:
        self.frames = frames
        self.quiet = threading.Event()  # never set: the wait of an empty bus
        super().__init__(channel="log")

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if not self.frames:
            self.quiet.wait(0.1 if timeout is None else min(timeout, 0.1))
            return None, False
        return self.frames.pop(0), False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        raise NotImplementedError


def _bridge_hears(monkeypatch: pytest.MonkeyPatch, frames: list[can.Message],
                  end: Callable[[asyncio.Event], None]) -> None:
    """``odocan bridge`` (patched) hears ``frames``; once it took every one in and its link is
    connected, ``end(stop)`` ends it (``stop``: what ``--duration`` sets)."""
    total = len(frames)
    feeds: list[BusFeed] = []
    monkeypatch.setattr(bridge_cmd, "open_bus", lambda args: _ListBus(list(frames)))

    class Fed(BusFeed):
        def start(self) -> None:
            super().start()
            feeds.append(self)

    def stop_when_fed(_duration_s: float, stop: asyncio.Event) -> None:
        bridge = feeds[0].bridge

        async def when_fed() -> None:
            async with asyncio.timeout(WAIT_S):
                while bridge.frames_in < total or not bridge.links[0].connected.is_set():
                    await asyncio.sleep(0.01)
            end(stop)

        tasks.append(asyncio.get_running_loop().create_task(when_fed(), name="test-deadline"))

    tasks: list[asyncio.Task[None]] = []
    monkeypatch.setattr(bridge_cmd, "BusFeed", Fed)
    monkeypatch.setattr(bridge_cmd, "_stop_after", stop_when_fed)  # the --duration's timer


def _duration_reached(stop: asyncio.Event) -> None:
    stop.set()


def _sigint(_stop: asyncio.Event) -> None:
    os.kill(os.getpid(), signal.SIGINT)  # as Ctrl-C, before the duration


def _argv(tmp_path: Path, *more: str) -> list[str]:
    robot = tmp_path / "kobuki_4m_s.toml"  # the drive's speed bound (test_pose_wrongs)
    robot.write_text(to_toml(KOBUKI))
    return ["bridge", "-i", "virtual", "--robot", str(robot), "--integrator", "rk2",
            "--duration", "600", *more]


@pytest.mark.parametrize("wrong", [True, False])
def test_the_bridge_exits_1_on_a_wrong_pose_and_says_it_last(
    wrong: bool, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    path, _ = _drive(tmp_path, wrong=wrong)
    _bridge_hears(monkeypatch, _messages(path), _duration_reached)
    code, _, err = run_cli(capsys, *_argv(tmp_path))
    last = err.splitlines()[-1]
    if wrong:
        assert code == 1, err
        assert last.startswith("bridge robot001: FAIL: the on-board pose was wrong in 1 episode ("
                               ), err
        assert "worst position 2.0" in last, last  # the bias began
        assert " mm off at 3.0" in last, last
        assert "(enc " not in last, last  # (a 4-bit counter locates nothing)
        assert last.endswith("; judged as robot 'kobuki' (--robot)"), last
    else:
        assert code == 0, err
        assert last.startswith("bridge robot001: PASS: the on-board pose right in "), err
    assert sum(line.startswith("bridge robot001: FAIL") for line in err.splitlines()) == wrong


def test_a_signal_before_the_duration_keeps_130_and_still_says_the_verdict(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
) -> None:
    path, _ = _drive(tmp_path, wrong=True)
    _bridge_hears(monkeypatch, _messages(path), _sigint)
    code, _, err = run_cli(capsys, *_argv(tmp_path))
    lines = err.splitlines()
    assert code == 130, err
    assert lines[-2].startswith("bridge robot001: FAIL: the on-board pose was wrong in 1 "), err
    assert lines[-1].startswith("bridge robot001: STOPPED by SIGINT at "), err  # last, as before


def test_a_distance_wrong_in_the_last_twists_fails_the_bridge(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
) -> None:
    """DISTANCE 2 mm off in the drive's last 30 frames (no ODOM_STATUS page after them: judged
    only at the watch's end, ``watchend``): the independent checker finds it wrong, and the
    bridge's verdict, taken after its watch ended, says so and exits 1 (``test_watch_end``'s
    drive, which the monitor fails the same way)."""
    drive = short_drive()
    synth = _synth(DISTANCE_KOBUKI, drive, off_by(2, len(drive[0]) - 30))
    assert not checker_passes(checker_errors_mm(synth.lines(), DISTANCE_KOBUKI))
    robot = tmp_path / "kobuki4.toml"  # the synthesized drive's speed bound (test_watch_end)
    robot.write_text(_profile_toml(DISTANCE_KOBUKI))
    _bridge_hears(monkeypatch, _messages(synth.write(tmp_path / "late.log")), _duration_reached)
    code, _, err = run_cli(capsys, "bridge", "-i", "virtual", "--robot", str(robot),
                           "--duration", "600")
    assert code == 1, err
    assert err.splitlines()[-1].startswith(
        "bridge robot001: FAIL: ODOM_TWIST DISTANCE off the reference's path length by "), err


@pytest.mark.parametrize("require", [False, True])
@pytest.mark.parametrize("heard", ["nothing", "no pose"])
def test_require_firmware_fails_a_bridge_that_judged_nothing(
    heard: str, require: bool, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A quiet bus, or a firmware whose poses never came (its ODOM_STATUS and the encoders
    only): UNJUDGED, exit 0; with ``--require-firmware`` FAIL, exit 1."""
    frames: list[can.Message] = []
    if heard == "no pose":
        path, _ = _drive(tmp_path, wrong=False)
        frames = [m for m in _messages(path) if m.arbitration_id not in (0x200, 0x201)]
    _bridge_hears(monkeypatch, frames, _duration_reached)
    code, _, err = run_cli(capsys, *_argv(tmp_path, *["--require-firmware"] * require))
    why = ("no firmware heard (no cyclic ODOM_MCU message)" if heard == "nothing" else
           "no on-board pose compared with the reference")
    expected = (f"bridge robot001: FAIL: {why}: nothing judged (--require-firmware)" if require
                else f"bridge robot001: UNJUDGED: {why}: nothing judged (--require-firmware "
                "fails it)")
    assert (code, err.splitlines()[-1]) == (int(require), expected), err


async def _retained_status(url: BrokerURL, robot: str) -> dict[str, Any]:
    """The retained ``status`` of ``robot`` as a subscriber that comes after the bridge gets
    it (the first message of a fresh subscription is the retained one)."""
    async with client(url) as sub:
        await sub.subscribe(f"odocan/{robot}/status", qos=1)
        async with asyncio.timeout(RETAINED_WAIT_S):
            async for message in sub.messages:
                assert message.retain, message.topic  # kept by the broker, not sent live
                assert isinstance(message.payload, bytes)
                status: dict[str, Any] = json.loads(message.payload)
                return status
    raise AssertionError("no retained status")


@pytest.mark.parametrize("wrong", [True, False])
def test_the_retained_offline_status_carries_the_printed_verdict(
    wrong: bool, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str], mosquitto: Mosquitto,  # noqa: F811
) -> None:
    """The bridge on mosquitto, its drive's pose wrong (FAIL) or right (PASS). Once it exited, a
    subscriber reads the retained ``offline`` status: its ``watch_verdict`` is the verdict line
    the bridge printed (name and reason), with the worst wrong episode the line names as
    ``pose_error`` (null on a PASS). Before (main): no ``watch_verdict`` in it."""
    path, _ = _drive(tmp_path, wrong=wrong)
    _bridge_hears(monkeypatch, _messages(path), _duration_reached)
    url = mosquitto.url()
    monkeypatch.setenv(PASSWORD_ENV, url.password or "")
    code, _, err = run_cli(capsys, *_argv(tmp_path, "--broker",
                                          f"mqtt://{url.username}@{url.host}:{url.port}"))
    assert code == int(wrong), err
    line = err.splitlines()[-1].removeprefix("bridge robot001: ")
    status = asyncio.run(_retained_status(url, "robot001"))
    assert (status["state"], status["reason"]) == ("offline", "bridge stopped"), status
    verdict = status.get("watch_verdict")
    assert isinstance(verdict, dict), status
    assert verdict["verdict"] == ("FAIL" if wrong else "PASS"), verdict
    assert f"{verdict['verdict']}: {verdict['reason']}" == line, (verdict, err)
    if wrong:
        assert verdict["pose_error"]["enc_seq"] == JUMP_AT, verdict  # where the bias began
        assert f"{verdict['pose_error']['dpos_mm']:.4f} mm" in line, (verdict, line)
        assert verdict["pose_error"] == status["pose_wrongs"]["worst"], status
    else:
        assert verdict["pose_error"] is None, verdict
