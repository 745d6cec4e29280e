"""``odocan run`` hands its frame collector the host's frames once per simulated second (the
collector is passive: ``sim.tickloop``), with or without a ``--log`` (its writer,
``host.io.recording.Recording``, is passive too), and judges the same either way; the log holds
every frame the collector got."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from odocan.host.cli.app import main
from odocan.host.io.collector import FrameCollector
from odocan.sim.framebatch import Received

WALL_KEYS = {"wall_seconds", "realtime_factor"}


def _calls(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """The size of every batch the collectors get."""
    sizes: list[int] = []
    plain = FrameCollector.on_frames

    def counted(self: FrameCollector, frames: list[Received]) -> None:
        sizes.append(len(frames))
        plain(self, frames)

    monkeypatch.setattr(FrameCollector, "on_frames", counted)
    return sizes


def _report(path: Path) -> Any:
    def drop(node: Any) -> Any:
        if isinstance(node, dict):
            return {k: drop(v) for k, v in node.items() if k not in WALL_KEYS and k != "inputs"}
        if isinstance(node, list):
            return [drop(v) for v in node]
        return node

    return drop(json.loads(path.read_text()))


def test_run_collects_a_simulated_second_at_once_and_judges_the_same(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    sizes = _calls(monkeypatch)
    argv = ["run", "--duration", "5", "--seed", "2"]
    assert main([*argv, "--report", str(tmp_path / "a.json")]) == 0
    # the first tick alone (the stop check after it), then a simulated second at a time
    assert len(sizes) == 6
    assert min(sizes[1:]) > 300  # a simulated second of the rig's ~360 frames
    quiet = list(sizes)
    sizes.clear()
    log = tmp_path / "drive.log"
    assert main([*argv, "--report", str(tmp_path / "b.json"), "--log", str(log)]) == 0
    assert sizes == quiet  # next to the log writer: the same batches, a second at a time
    assert sum(quiet) == sum(1 for line in log.read_text().splitlines() if line.strip())
    assert _report(tmp_path / "a.json") == _report(tmp_path / "b.json")
    capsys.readouterr()
