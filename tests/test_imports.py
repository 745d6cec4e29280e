"""A command imports what it runs, not what the others need (start-up is part of its speed).

Each check runs a fresh interpreter (``sys.modules`` of this test process is shared with every
other test), runs the command through ``main`` and lists the heavy packages it loaded. Not a
timing assertion: what is imported or not, which does not depend on the machine's load.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from odocan.host.cli.app import main

HEAVY = ("matplotlib", "aiomqtt", "amqtt", "paho", "pyarrow", "foxglove", "foxglove_sdk", "mcap",
         "cryptography", "dask", "distributed")
PROBE = """
import json, sys
from odocan.host.cli.app import main
code = main(sys.argv[1:])
print(json.dumps({"code": code, "modules": sorted({m.split(".")[0] for m in sys.modules})}))
"""


def imported_by(*argv: str) -> tuple[int, set[str]]:
    """Exit code and top-level packages imported by ``odocan ARGV`` in a fresh interpreter."""
    done = subprocess.run([sys.executable, "-c", PROBE, *argv], capture_output=True, text=True,
                          timeout=300, check=False)
    last = json.loads(done.stdout.strip().splitlines()[-1])
    return int(last["code"]), set(last["modules"])


@pytest.fixture(scope="module")
def small_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    log = tmp_path_factory.mktemp("imports") / "drive.log"
    assert main(["run", "--duration", "2", "--seed", "3", "--log", str(log)]) == 0
    return log


def test_analyze_imports_nothing_heavy_it_does_not_use(small_log: Path) -> None:
    code, modules = imported_by("analyze", str(small_log))
    assert code == 0
    assert modules.isdisjoint(HEAVY), sorted(modules & set(HEAVY))
    assert {"numpy", "cantools", "rich"} <= modules  # the probe sees what analyze does use


def test_the_probe_sees_heavy_imports_when_a_command_uses_them(
    small_log: Path, tmp_path: Path
) -> None:
    """The same probe on ``--plot``: matplotlib is loaded, so the check above can fail."""
    code, modules = imported_by("analyze", str(small_log), "--plot", str(tmp_path / "p.png"))
    assert code == 0
    assert "matplotlib" in modules


def test_the_full_parser_still_lists_every_command() -> None:
    """With no command named, every subparser is still built (help lists them all)."""
    done = subprocess.run([sys.executable, "-m", "odocan", "--help"], capture_output=True,
                          text=True, timeout=300, check=False)
    assert done.returncode == 0
    for command in ("run", "analyze", "replay", "monitor", "bridge", "fleet", "busload"):
        assert f"    {command}" in done.stdout
