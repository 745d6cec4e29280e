"""A command imports what it runs, not what the others need (start-up is part of its speed).

Each check runs a fresh interpreter (``sys.modules`` of this test process is shared with every
other test), runs the command through ``main`` and lists the heavy packages it loaded. Not a
timing assertion: what is imported or not, which does not depend on the machine's load.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from odocan.host.cli.app import SUBCOMMANDS, main

HEAVY = ("matplotlib", "aiomqtt", "amqtt", "paho", "pyarrow", "foxglove", "foxglove_sdk", "mcap",
         "cryptography", "dask", "distributed")
MQTT = ("aiomqtt", "paho")
# What each command's start-up (its module and its parser) may not import: HEAVY, less what the
# command is for. monitor's --broker, bridge and fleet speak MQTT; bridge and fleet sign commands
# with SecOC (cryptography's AES-CMAC). run and analyze parse (and refuse bad usage) without rich:
# it comes with the summary.
FORBIDDEN = {
    **{name: frozenset(HEAVY) for name in SUBCOMMANDS},
    "run": frozenset({*HEAVY, "rich"}),
    "analyze": frozenset({*HEAVY, "rich"}),
    "monitor": frozenset(HEAVY) - set(MQTT),
    "bridge": frozenset(HEAVY) - {*MQTT, "cryptography"},
    "fleet": frozenset(HEAVY) - {*MQTT, "cryptography"},
}
PROBE = """
import json, sys
from odocan.host.cli.app import SUBCOMMANDS, main
code = main(sys.argv[1:])
print(json.dumps({"code": code, "modules": sorted({m.split(".")[0] for m in sys.modules})}))
"""
VERSION_PROBE = """
import json, sys
from odocan.host.cli.app import main
try:
    main(["--version"])
except SystemExit as done:
    assert done.code == 0, done.code
print(json.dumps(sorted(sys.modules)))
"""
STARTUP_PROBE = """
import json, sys
from odocan.host.cli.app import build_parser, named_command
build_parser(named_command(sys.argv[1:]))
print(json.dumps({"code": 0, "modules": sorted({m.split(".")[0] for m in sys.modules})}))
"""


def imported_by(
    *argv: str, probe: str = PROBE, env: dict[str, str] | None = None
) -> tuple[int, set[str]]:
    """Exit code and top-level packages imported by ``odocan ARGV`` in a fresh interpreter."""
    done = subprocess.run([sys.executable, "-c", probe, *argv], capture_output=True, text=True,
                          timeout=300, check=False, env=env)
    last = json.loads(done.stdout.strip().splitlines()[-1])
    return int(last["code"]), set(last["modules"])


@pytest.fixture(scope="module")
def small_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    log = tmp_path_factory.mktemp("imports") / "drive.log"
    assert main(["run", "--duration", "2", "--seed", "3", "--log", str(log)]) == 0
    return log


def test_analyze_imports_nothing_heavy_it_does_not_use(small_log: Path, tmp_path: Path) -> None:
    """Nor, once the DBC's plan is cached (``host.protocol.dbcplan``), cantools or python-can:
    the first run parses the DBC with cantools, the next ones read the plan."""
    env = dict(os.environ, ODOCAN_CACHE_DIR=str(tmp_path / "cache"))
    for run in ("cold", "warm"):
        code, modules = imported_by("analyze", str(small_log), env=env)
        assert code == 0
        assert modules.isdisjoint(HEAVY), sorted(modules & set(HEAVY))
        assert {"numpy", "rich"} <= modules  # the probe sees what analyze does use
        assert ("cantools" in modules) == (run == "cold"), run
        assert ("can" in modules) == (run == "cold"), run  # cantools imports python-can


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


@pytest.mark.parametrize("command", SUBCOMMANDS)
def test_each_command_starts_without_what_it_does_not_use(command: str) -> None:
    """What ``odocan COMMAND`` imports before it runs (its module, its parser): none of its
    forbidden packages."""
    _, modules = imported_by(command, probe=STARTUP_PROBE)
    assert "odocan" in modules  # the probe ran
    assert modules.isdisjoint(FORBIDDEN[command]), sorted(modules & FORBIDDEN[command])


def test_the_startup_probe_sees_a_command_s_own_heavy_imports() -> None:
    """The same probe on ``bridge``: MQTT is loaded, so the check above can fail."""
    _, modules = imported_by("bridge", probe=STARTUP_PROBE)
    assert set(MQTT) <= modules


def test_run_imports_foxglove_mqtt_and_cryptography_only_when_asked(tmp_path: Path) -> None:
    """A whole ``odocan run``: no Foxglove server (nor the monitor's MQTT fleet view behind
    it), no AES-CMAC without ``--secoc-key``; nor, once the DBC's plan is cached, cantools (the
    rig's cycle times come from the plan too: ``sim.contract.read_as``)."""
    env = dict(os.environ, ODOCAN_CACHE_DIR=str(tmp_path / "cache"))
    for run in ("cold", "warm"):
        code, modules = imported_by("run", "--duration", "1", "--seed", "2",
                                    "--report", str(tmp_path / "r.json"), env=env)
        assert code == 0
        assert modules.isdisjoint(HEAVY), sorted(modules & set(HEAVY))
        assert {"numpy", "can", "rich"} <= modules  # the probe sees what run does use
        assert ("cantools" in modules) == (run == "cold"), run


def test_version_imports_no_library_and_prints_the_package_version() -> None:
    """``odocan --version``: no subcommand built, nothing heavy imported, not even numpy,
    python-can, cantools or rich; it prints the version pyproject.toml gives the package."""
    from importlib.metadata import version

    done = subprocess.run([sys.executable, "-c", VERSION_PROBE], capture_output=True, text=True,
                          timeout=300, check=False)
    printed, last = done.stdout.strip().splitlines()
    modules = set(json.loads(last))
    assert printed == f"odocan {version('odocan')}"
    assert not {m for m in modules if m.startswith("odocan.host.cli.subparsers.")}
    top = {m.split(".")[0] for m in modules}
    assert top.isdisjoint({*HEAVY, "numpy", "can", "cantools", "rich"}), top


def test_python_can_errors_stay_usage_errors_though_app_does_not_import_can() -> None:
    """``main`` no longer imports python-can to catch its errors; a ``CanError`` a command
    raises (python-can then imported) is still a one-line usage error, anything else is not."""
    import can

    from odocan.host.cli.app import is_usage_error
    from odocan.sim.exceptions import ConfigurationError

    assert is_usage_error(can.CanInitializationError("no such channel"))
    assert is_usage_error(ConfigurationError("bad value"))
    assert is_usage_error(FileNotFoundError(2, "No such file", "x.log"))
    assert not is_usage_error(ValueError("a bug"))


LOWER_ROOMS = ("io", "protocol", "judge")  # README: cli -> {experiments, mqtt, testkit, report}
UPPER_ROOMS = ("report", "cli", "mqtt", "experiments", "testkit")  # -> judge -> protocol -> io
# Arrows that still point back up, each named (a fix shrinks this; a new one fails the test).
KNOWN_BACK_ARROWS: set[tuple[str, str]] = set()


def imported_modules(path: Path) -> set[str]:
    """Every module ``path`` imports, at the top or lazily inside a function (absolute names;
    ``from odocan.host import report`` counts as ``odocan.host.report``)."""
    import ast

    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            assert node.level == 0, f"{path}: relative import"
            base = node.module or ""
            names.add(base)
            if base in ("odocan", "odocan.host"):  # the names are modules (rooms)
                names.update(f"{base}.{alias.name}" for alias in node.names)
    return names


def back_arrows(host: Path) -> set[tuple[str, str]]:
    """(file under host/, module) for each import of an upper room by a lower room."""
    upper = tuple(f"odocan.host.{room}" for room in UPPER_ROOMS)
    found = set()
    for room in LOWER_ROOMS:
        for path in sorted((host / room).rglob("*.py")):
            for name in imported_modules(path):
                if name in upper or name.startswith(tuple(f"{u}." for u in upper)):
                    found.add((path.relative_to(host).as_posix(), name))
    return found


def test_io_protocol_and_judge_import_no_upper_room(tmp_path: Path) -> None:
    """io/, protocol/ and judge/ import nothing of report/, cli/, mqtt/, experiments/ or
    testkit/ (what they share with those rooms lives at host/ level: ``host.outputs``,
    ``host.jsonutil``), but for the arrows named in ``KNOWN_BACK_ARROWS``."""
    host = Path(__file__).resolve().parents[1] / "host"
    assert back_arrows(host) == KNOWN_BACK_ARROWS
    # the check sees an arrow back, lazy or not, in any spelling
    planted = tmp_path / "judge"
    planted.mkdir()
    (planted / "x.py").write_text(
        "def f():\n    from odocan.host import report\n    import odocan.host.mqtt.bridge\n"
    )
    assert back_arrows(tmp_path) == {
        ("judge/x.py", "odocan.host.report"),
        ("judge/x.py", "odocan.host.mqtt.bridge"),
    }


def test_bare_help_imports_no_subcommand() -> None:
    """``odocan --help`` lists every command without importing one (nor numpy, python-can,
    cantools, rich)."""
    probe = VERSION_PROBE.replace('["--version"]', '["--help"]')
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                          timeout=300, check=False)
    modules = set(json.loads(done.stdout.strip().splitlines()[-1]))
    assert "    key" in done.stdout
    assert "    run" in done.stdout
    assert not {m for m in modules if m.startswith("odocan.host.cli.subparsers.")}
    top = {m.split(".")[0] for m in modules}
    assert top.isdisjoint({*HEAVY, "numpy", "can", "cantools", "rich"}), top


BLAS_PROBE = """
import os, sys
from odocan.host.cli import main
try:
    main(["--version"])
except SystemExit:
    pass
import numpy
print(os.environ.get("OPENBLAS_NUM_THREADS"))
"""


@pytest.mark.parametrize(("given", "seen"), [(None, "1"), ("3", "3")])
def test_the_command_runs_blas_on_one_thread_unless_told(given: str | None, seen: str) -> None:
    """``main`` sets OpenBLAS to one thread before numpy loads (``host.cli.BLAS_THREADS``: no
    spinning thread pool, the same dot-product bits on every machine); a user's value stays."""
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if given is not None:
        env["OPENBLAS_NUM_THREADS"] = given
    done = subprocess.run([sys.executable, "-c", BLAS_PROBE], capture_output=True, text=True,
                          env=env, timeout=300, check=True)
    assert done.stdout.strip().splitlines()[-1] == seen
