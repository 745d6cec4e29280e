"""A log with an applied config, streamed by ``odocan analyze`` (issue #11/#13: memory that grows
with the log; ``host.judge.configs.ConfigPages``).

Before, the CLI's PROFILE-page checks (the page before the first config's APPLY: the robot's
speed bound and the line naming a wrong ``--robot``; the pages after each config against its
robot: ``configs.running_before_configs``, ``later_mismatches``) read the whole log, so the
streamed judge refused every such log ("a config was applied: its PROFILE pages are judged
whole") and an hour's drive with one config at its start was read whole. Now they are read from
the stream's spilled frames: the report (the JSON ``--report`` writes, diagnosis included) is
the whole log's, byte for byte, for the drive of ``tests/test_analyze_config.py`` (kobuki, a
config NACKed at 2 s, one ACKed at 3 s: inside the head ``head_profile`` reads, so the page
before the APPLY is not the head's last), its firmware right or ignoring the config, judged as
kobuki and as pmir (a wrong ``--robot``: the pages' lines said).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from odocan.host.cli.app import main
from odocan.host.judge.configs import ConfigPages
from odocan.host.judge.stream_analysis import analyze_file
from odocan.sim import robot
from tests.test_analyze_config import _drive


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[bool, Path]]:
    """The drive's candump log, by whether the firmware ignores the config."""
    folder = tmp_path_factory.mktemp("configpages")
    with pytest.MonkeyPatch.context() as monkeypatch:
        paths = {}
        for ignores in (False, True):
            lines = [f"({m.timestamp:.6f}) vcan0 {m.arbitration_id:03X}#"
                     f"{bytes(m.data).hex().upper()}" for m in _drive(ignores, monkeypatch)]
            paths[ignores] = folder / f"config-{'ignored' if ignores else 'taken'}.log"
            paths[ignores].write_text("\n".join(lines) + "\n")
            monkeypatch.undo()
        yield paths


def _cli(log: Path, name: str, stream: str, report: Path) -> tuple[int, str]:
    code = main(["analyze", str(log), "--robot", name, "--stream", stream, "--chunk-frames",
                 "500", "--report", str(report)])
    return code, report.read_text()


@pytest.mark.parametrize("name", ["kobuki", "pmir"])
@pytest.mark.parametrize("ignores", [False, True])
def test_streamed_the_report_is_the_whole_logs(logs: dict[bool, Path], ignores: bool, name: str,
                                               tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    whole = _cli(logs[ignores], name, "never", tmp_path / "whole.json")
    capsys.readouterr()
    streamed = _cli(logs[ignores], name, "always", tmp_path / "streamed.json")
    assert "not streamable" not in capsys.readouterr().err  # before: judged whole, said
    assert streamed == whole
    assert whole[0] == (0 if name == "kobuki" and not ignores else 1)


def test_the_pages_are_read_from_the_stream(logs: dict[bool, Path]) -> None:
    """The page before the APPLY and the one after it, from the spill (no refusal)."""
    pages = ConfigPages(robot.load("kobuki"))
    analyze_file(logs[False], pages.profile, chunk_frames=97, whole_on_config=True,
                 config_pages=pages)
    assert pages.before is not None
    assert len(pages.after) == 1
    assert pages.after[0][1] is not None
    assert pages.before.profile_crc != pages.after[0][1].profile_crc  # the wheelbase changed


def test_a_new_speed_bound_the_page_before_the_apply_is_the_runnings(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The config also raises MAX_WHEEL_SPEED (0.7 -> 1.5 m/s): the log's head (``head_profile``,
    all 9 s of it) ends on the new bound, the page before the APPLY holds the old one, which the
    whole log's path judges with and names ``--robot kobuki`` by; the stream now the same."""
    import tests.test_analyze_config as drive_module

    plain = drive_module._config
    with pytest.MonkeyPatch.context() as monkeypatch:
        monkeypatch.setattr(drive_module, "_config",
                            lambda **changed: {**plain(**changed), "max_wheel_speed_m_s": 1.5})
        messages = _drive(False, monkeypatch)
    log = tmp_path / "faster.log"
    log.write_text("".join(f"({m.timestamp:.6f}) vcan0 {m.arbitration_id:03X}#"
                           f"{bytes(m.data).hex().upper()}\n" for m in messages))
    pages = ConfigPages(robot.load("kobuki"))
    analyze_file(log, pages.profile, whole_on_config=True, config_pages=pages)
    assert pages.before is not None
    assert pages.after[0][1] is not None
    assert (pages.before.max_wheel_speed_mm_s, pages.after[0][1].max_wheel_speed_mm_s) == (
        700, 1500)
    whole = _cli(log, "kobuki", "never", tmp_path / "whole.json")
    streamed = _cli(log, "kobuki", "always", tmp_path / "streamed.json")
    assert "not streamable" not in capsys.readouterr().err
    assert streamed == whole
