"""``host.accel``: the per-frame path compiled with mypyc publishes what pure Python publishes,
byte for byte, and a build is only ever used for the exact sources it was made from."""

from __future__ import annotations

import importlib.machinery
import importlib.util
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from odocan.host import accel
from tests.requires import IN_CI

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench" / "bridge_frames.py"


def _env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != accel.ENV}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    return {**env, **extra}


def test_key_names_every_source_byte(tmp_path: Path) -> None:
    """Any edit of any module (not only a compiled one: mypyc inlines other modules' constants
    and layouts) makes another key; the same bytes the same key."""
    (tmp_path / "sub").mkdir()
    (tmp_path / "a.py").write_text("X = 1\n")
    (tmp_path / "sub" / "b.py").write_text("Y = 2\n")
    first = accel.sources_key(tmp_path)
    assert accel.sources_key(tmp_path) == first
    (tmp_path / "sub" / "b.py").write_text("Y = 3\n")
    assert accel.sources_key(tmp_path) != first
    (tmp_path / "sub" / "b.py").write_text("Y = 2\n")
    assert accel.sources_key(tmp_path) == first


def test_without_a_build_pure_python_with_one_line(tmp_path: Path) -> None:
    """No build and none asked for: pure Python, said in one line on stderr, no finder."""
    code = ("from odocan.host import accel; import sys; "
            "print(accel.install(build=False), bool(accel.active()))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=_env(ODOCAN_ACCEL_CACHE=str(tmp_path)), check=True)
    assert done.stdout.split() == ["False", "False"]
    assert done.stderr.count("\n") == 1
    assert "pure Python (no build at" in done.stderr


def _bench(env: dict[str, str], firmware: str) -> str:
    """The bench's digest line (publications, their digest, the frames' digest) for a small
    fleet whose boards run ``firmware``."""
    done = subprocess.run([sys.executable, str(BENCH), "--robots", "3", "--ticks", "300",
                           "--firmware", firmware],
                          capture_output=True, text=True, env=env, check=True, timeout=3600)
    found = re.search(r"(\d+ publications, digest \w+, frames \w+)", done.stdout)
    assert found, done.stdout + done.stderr
    return found.group(1)


def _why_not_compiled() -> str | None:
    """Why the compiled path is not compared here (None: it is)."""
    if importlib.util.find_spec("mypyc") is None or shutil.which("gcc") is None:
        return "the compiled path needs mypyc (pip install mypy) and gcc"
    if os.environ.get("ODOCAN_ACCEL_TEST") != "1" and not IN_CI and not accel.built(
            accel.cache_root() / accel.sources_key()):
        return ("no mypyc build of these sources (building takes minutes, kept out of a "
                "developer's `make test`; CI builds it): python -m odocan.host.accel, or "
                "ODOCAN_ACCEL_TEST=1 to build here")
    return None


@pytest.mark.slow
@pytest.mark.skipif(_why_not_compiled() is not None, reason=str(_why_not_compiled()))
def test_compiled_publishes_the_same_bytes() -> None:
    """Built (minutes, once per version of the sources, in the user's cache) and loaded, the
    compiled modules publish the same bytes as the pure ones from the same frames."""
    env = _env(**{accel.ENV: "1"})
    probe = ("import odocan.host.mqtt.telemetry as t, odocan.host.accel as a; "
             "print(t.__file__, len(a.active()))")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                          env=env, check=True, timeout=3600)
    path, count = done.stdout.split()
    assert path.endswith(importlib.machinery.EXTENSION_SUFFIXES[0]), done.stderr
    assert int(count) >= len(accel.MODULES)
    for firmware in ("python", "c"):  # the same frames and publications, either board
        assert _bench(env, firmware) == _bench(_env(), firmware), firmware


@pytest.mark.slow
@pytest.mark.skipif(_why_not_compiled() is not None, reason=str(_why_not_compiled()))
def test_fleet_accel_runs_its_worker_compiled(tmp_path: Path) -> None:
    """``odocan fleet --accel`` with one worker: the worker is spawned (its modules imported
    afresh, compiled), its verdicts as pure Python's, and the start line says so. On the
    paced clock (``tests.fleet_paced``, in the spawned worker too): on the real one a loaded
    machine's 1.4 s stall at the first tick halted every board and the one-second run ended
    without the PASS checked (verified: the worker SIGSTOPped 1.4 s, worst tick 0.0 ms late)."""
    report = tmp_path / "fleet.json"
    done = subprocess.run([sys.executable, "-m", "tests.fleet_paced", "fleet", "-n", "2",
                           "--duration", "1",
                           "--accel", "--max-miss-ratio", "1", "--report", str(report)],
                          capture_output=True, text=True, env=_env(), timeout=3600, check=False)
    assert done.returncode == 0, done.stderr
    assert "compiled per-frame path (mypyc)" in done.stderr
    assert "pure Python" not in done.stderr
    assert len(json.loads(report.read_text())["workers"]) == 1  # spawned, not in process
