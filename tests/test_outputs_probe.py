"""Every output path is proved writable by opening it before the work, not by permission bits.

Found from outside: ``odocan run --report /proc/x.json`` drove the whole run, printed PASS, then
failed writing the report (exit 2). As root ``os.access`` says yes to a new file in ``/proc``;
only creating it tells. Each subcommand that writes after long work must refuse such a path up
front: exit 2, one ``error:`` line naming the path, nothing run (no summary on stdout).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from odocan.host.cli.app import main
from odocan.host.outputs import check_writable, check_writable_dir
from odocan.sim.exceptions import ConfigurationError

UNWRITABLE = "/proc/odocan_nav_probe.json"  # procfs: no new file, whoever asks


def _commands(log: Path) -> list[list[str]]:
    bad = UNWRITABLE
    return [
        ["run", "--duration", "1", "--report", bad],
        ["run", "--duration", "1", "--junit", bad],
        ["run", "--duration", "1", "--log", bad.replace(".json", ".log")],
        ["run", "--duration", "1", "--plot", bad.replace(".json", ".png")],
        ["run", "--duration", "1", "--mcap", bad.replace(".json", ".mcap")],
        ["run", "--duration", "1", "--parquet", "/proc/odocan_nav_probe_dir"],
        ["analyze", str(log), "--report", bad],
        ["replay", str(log), "--log", bad.replace(".json", ".log")],
        ["umbmark", "--report", bad],
        ["calibrate", "--report", bad],
        ["calibrate", "--write-robot", bad.replace(".json", ".toml")],
        ["experiment", "seed002", "--report", bad],
        ["fleet", "--report", bad],
    ]


@pytest.mark.parametrize("index", range(13))
def test_an_output_in_proc_is_refused_before_the_work(
    index: int, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = tmp_path / "drive.log"
    log.write_text("(0.000000) vcan0 123#00\n")
    argv = _commands(log)[index]
    code = main(argv)
    out, err = capsys.readouterr()
    assert code == 2, (argv, out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("error: "), err
    assert "/proc/odocan_nav_probe" in lines[0], err
    assert "PASS" not in out, out
    assert "FAIL" not in out, out
    assert not Path(UNWRITABLE).exists()


def test_the_probe_leaves_no_file_and_keeps_an_existing_one(tmp_path: Path) -> None:
    new = tmp_path / "new.json"
    check_writable(new, "--report")
    assert not new.exists()
    old = tmp_path / "old.json"
    old.write_text("kept")
    check_writable(old, "--report")
    assert old.read_text() == "kept"
    check_writable_dir(tmp_path, "--parquet")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.json"]


def test_a_new_file_in_proc_and_a_proc_directory_are_refused() -> None:
    with pytest.raises(ConfigurationError, match=r"--report /proc/odocan_nav_probe\.json"):
        check_writable(Path(UNWRITABLE), "--report")
    with pytest.raises(ConfigurationError, match="--parquet /proc"):
        check_writable_dir(Path("/proc"), "--parquet")


def test_a_dangling_symlink_is_probed_at_its_target(tmp_path: Path) -> None:
    """The writer follows the link and creates its target: so does the probe (and removes it);
    a link into a missing directory is refused naming that directory."""
    link = tmp_path / "report.json"
    link.symlink_to(tmp_path / "target.json")
    check_writable(link, "--report")
    assert link.is_symlink()
    assert not (tmp_path / "target.json").exists()
    away = tmp_path / "away.json"
    away.symlink_to(tmp_path / "nowhere" / "target.json")
    with pytest.raises(ConfigurationError, match="nowhere does not exist"):
        check_writable(away, "--report")
