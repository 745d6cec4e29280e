"""The live judges' fast path (``livewindow.named_plain``: a pose half neither queued nor held
resolved in plain Python) gives what ``samples.match_encoder`` over the whole window gives: on a
plain drive, a babbled one (bursts), a lossy one (ENC_E2E_LOST grows: the allowance) and a
reboot (with and without the boot summary), the monitor's and the bridge's every sample, error
statistic, allowance, stall and start are equal, bit for bit, with ``PoseTracker.fast_path`` on
and off. And the fast path is taken (most halves skip ``match_encoder``) while a burst still
goes to ``match_encoder`` (the babbled drive calls it).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from odocan.host.judge import livewindow
from odocan.host.judge.livepose import Sample
from odocan.host.judge.samples import match_encoder
from odocan.host.judge.tracking import PoseTracker
from odocan.sim.robot import load
from tests.test_analysis_reboot import REBOOT, rebooting_drive
from tests.test_babble_firmware import _run_log
from tests.test_judge_lossy import _run
from tests.test_live_reboot import bridge_of, monitor_of


def _plain_log(tmp_path: Path) -> Path:
    log = tmp_path / "plain.log"
    subprocess.run([sys.executable, "-m", "odocan", "run", "--robot", "pmir", "--seed", "5",
                    "--duration", "4", "--log", str(log)],
                   capture_output=True, timeout=300, check=True)
    return log


def _reboot_log(tmp_path: Path, boot_summary: bool) -> Path:
    synth = rebooting_drive(load("kobuki"), "exact", bias={k: 2 for k in range(REBOOT, 400)})
    if not boot_summary:
        synth.groups[REBOOT] = [line for line in synth.groups[REBOOT]
                                if " 380#" not in line.upper()]
    return synth.write(tmp_path / f"reboot_{boot_summary}.log")


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, str]]:
    tmp = tmp_path_factory.mktemp("fast")
    return {
        "plain": (_plain_log(tmp), "pmir"),
        "babble": (_run_log(tmp), "pmir"),
        "lossy": (_run(tmp)[0], "pmir"),
        "reboot": (_reboot_log(tmp, True), "kobuki"),
        "reboot_no_summary": (_reboot_log(tmp, False), "kobuki"),
    }


def _judged(path: Path, robot: str) -> tuple[list[Any], int, int]:
    """What the monitor and the bridge judge of the log: every sample settled and their final
    statistics; and how many halves went to ``match_encoder`` and were resolved in all."""
    samples: list[list[Sample]] = [[], []]
    calls = {"slow": 0, "named": 0}
    take, named, match = PoseTracker.take_samples, PoseTracker.named, match_encoder

    def taking(self: PoseTracker) -> list[Sample]:
        got = take(self)
        samples[getattr(self, "_which", 0)].extend(got)
        return got

    def counting_named(self: PoseTracker, *args: Any) -> tuple[int, bool]:
        calls["named"] += 1
        return named(self, *args)

    def counting_match(*args: Any, **kwargs: Any) -> Any:
        calls["slow"] += 1
        return match(*args, **kwargs)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(PoseTracker, "take_samples", taking)
        patch.setattr(PoseTracker, "named", counting_named)
        patch.setattr(livewindow, "match_encoder", counting_match)
        patch.setattr(PoseTracker, "_which", 0, raising=False)
        monitor = monitor_of(path, robot, "exact")
        patch.setattr(PoseTracker, "_which", 1, raising=False)
        bridge = bridge_of(path, robot, "exact")
    judged: list[Any] = [samples]
    for tracker in (monitor.tracker, bridge.tracker):
        judged.append((tracker.snapshot(), vars(tracker.vs_reference), vars(tracker.vs_truth),
                       tracker.allowance_m(), tracker.max_beyond_allowance_m, tracker.stall.stalls,
                       tracker.reference_starts, list(tracker.losses.spans)))
    return judged, calls["slow"], calls["named"]


@pytest.mark.parametrize("name", ["plain", "babble", "lossy", "reboot", "reboot_no_summary"])
def test_the_fast_path_judges_as_match_encoder_does(
    logs: dict[str, tuple[Path, str]], name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    path, robot = logs[name]
    fast, fast_calls, halves = _judged(path, robot)
    monkeypatch.setattr(PoseTracker, "fast_path", False)
    slow, slow_calls, slow_halves = _judged(path, robot)
    samples = fast[0]
    print(f"\n{name}: {len(samples[0])} + {len(samples[1])} samples, {halves} halves, "
          f"match_encoder {fast_calls} (fast path) vs {slow_calls} calls")
    assert len(samples[0]) > 100  # something judged, by the monitor
    assert len(samples[1]) > 100  # and by the bridge
    assert fast == slow
    assert halves == slow_halves == slow_calls
    assert fast_calls < halves  # the fast path is taken
    if name == "plain":
        assert fast_calls <= halves // 100  # and is the common case
    if name == "babble":
        assert fast_calls > 0  # bursts still go to match_encoder
