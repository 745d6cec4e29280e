"""``-`` as an output path is standard output, as Unix tools take it (``--report -``,
``--junit -``): the output alone on stdout, the summary on stderr, and no file named ``-``.

Before, ``analyze --report -`` wrote a file named ``-`` in the working directory and printed only
the summary. The command runs in a process of its own so that stdout is a real pipe, as a shell
gives it (``odocan analyze drive.log --report - | jq .passed``).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

import odocan

TREE = Path(odocan.__file__).resolve().parents[1]


def _odocan(*argv: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, PYTHONPATH=str(TREE))
    return subprocess.run([sys.executable, "-m", "odocan", *argv], cwd=cwd, env=env,
                          capture_output=True, text=True, check=False, timeout=300)


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 2 s drive's candump log and, next to it, its JSON report as a file."""
    folder = tmp_path_factory.mktemp("dash")
    done = _odocan("run", "--duration", "2", "--firmware", "python", "--log", "drive.log",
                   cwd=folder)
    assert done.returncode == 0, done.stderr
    done = _odocan("analyze", "drive.log", "--report", "drive.json", cwd=folder)
    assert done.returncode == 0, done.stderr
    return folder / "drive.log"


def test_analyze_report_dash_is_the_report_alone_on_stdout(drive: Path) -> None:
    done = _odocan("analyze", drive.name, "--report", "-", cwd=drive.parent)
    assert done.returncode == 0, done.stderr
    assert not (drive.parent / "-").exists()
    report = json.loads(done.stdout)  # the whole of stdout: the summary is not in it
    assert report == json.loads((drive.parent / "drive.json").read_text(encoding="utf-8"))
    assert report["passed"] is True
    assert "PASS" in done.stderr  # the summary, on stderr


def test_analyze_junit_dash_is_the_xml_alone_on_stdout(drive: Path) -> None:
    done = _odocan("analyze", drive.name, "--junit", "-", "--report", "r.json",
                   cwd=drive.parent)
    assert done.returncode == 0, done.stderr
    assert not (drive.parent / "-").exists()
    suite = ET.fromstring(done.stdout)
    assert suite.find(".//testcase") is not None
    assert "PASS" in done.stderr


def test_two_outputs_on_stdout_are_refused(drive: Path) -> None:
    done = _odocan("analyze", drive.name, "--junit", "-", "--report", "-", cwd=drive.parent)
    assert (done.returncode, done.stdout) == (2, "")
    assert done.stderr.count("\n") == 1, done.stderr
    assert "also an output" in done.stderr


@pytest.mark.parametrize("command", ["analyze", "run", "busload"])
def test_the_help_says_dash_is_stdout(command: str, tmp_path: Path) -> None:
    done = _odocan(command, "--help", cwd=tmp_path)
    assert done.returncode == 0
    assert "- for stdout" in " ".join(done.stdout.split())
