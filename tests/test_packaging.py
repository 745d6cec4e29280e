"""odocan as a user installs it: the wheel and the sdist, each into a fresh venv, outside the repo.

What an editable install hides (a package left out of the wheel, the DBC found through the source
tree, a top-level ``firmware`` shadowing a user's own) shows here: the installed ``odocan`` runs a
drive, analyses its log and serves the ``odocan_rig`` fixture to a test file in a folder of its own.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tarfile
import venv
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
EXTERNAL_TEST = '''
import pytest


@pytest.mark.odocan(robot="kobuki", integrator="rk2")
def test_a_straight_drive_matches_the_reference(odocan_rig):
    rig = odocan_rig(seed=4)
    rig.drive("straight", seconds=2.0)
    rig.assert_pose_matches_reference(position_m=1e-4)
'''

pytestmark = pytest.mark.slow


def _run(argv: list[str], cwd: Path, timeout_s: float = 600) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    done = subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=timeout_s, check=False)
    assert done.returncode == 0, f"{argv} -> {done.returncode}\n{done.stdout}\n{done.stderr}"
    return done


@pytest.fixture(scope="module")
def dists(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The wheel and the sdist, built from the checkout by PyPA's ``build``."""
    out = tmp_path_factory.mktemp("dist")
    _run([sys.executable, "-m", "build", "--outdir", str(out), str(ROOT)], cwd=out)
    (wheel,) = out.glob("odocan-*.whl")
    (sdist,) = out.glob("odocan-*.tar.gz")
    return {"wheel": wheel, "sdist": sdist}


def test_the_wheel_has_one_top_level_name_and_its_data(dists: dict[str, Path]) -> None:
    names = zipfile.ZipFile(dists["wheel"]).namelist()
    top = {n.split("/")[0] for n in names if not n.split("/")[0].endswith(".dist-info")}
    assert top == {"odocan"}
    for needed in ("odocan/dbc/odocan.dbc", "odocan/sim/robots/pmir.toml",
                   "odocan/sim/robots/kobuki.toml", "odocan/host/mqtt/bridge.py",
                   "odocan/host/cli/subparsers/run.py", "odocan/host/experiments/umbmark.py",
                   "odocan/__main__.py", "odocan/firmware/py.typed"):
        assert needed in names, needed
    assert not any(n.startswith(("odocan/tests/", "tests/", "tools/")) for n in names)


def test_the_sdist_carries_the_sources_and_the_dbc(dists: dict[str, Path]) -> None:
    with tarfile.open(dists["sdist"]) as sdist:
        names = {n.split("/", 1)[1] for n in sdist.getnames() if "/" in n}
    for needed in ("pyproject.toml", "odocan/dbc/odocan.dbc", "odocan/sim/robots/pmir.toml",
                   "odocan/firmware/odometry.py", "odocan/host/cli/app.py"):
        assert needed in names, needed


@pytest.mark.parametrize("kind", ["wheel", "sdist"])
def test_an_installed_odocan_runs_analyzes_and_serves_its_fixture(
    kind: str, dists: dict[str, Path], tmp_path: Path
) -> None:
    env_dir = tmp_path / "venv"
    venv.EnvBuilder(with_pip=True).create(env_dir)
    python = env_dir / "bin" / "python"
    _run([str(python), "-m", "pip", "install", "--quiet", str(dists[kind]), "pytest"], cwd=tmp_path)
    work = tmp_path / "user"
    work.mkdir()
    # The user's own packages named like ours must not be shadowed, nor shadow odocan.
    (work / "firmware").mkdir()
    (work / "firmware" / "__init__.py").write_text("MINE = True\n")

    odocan = str(env_dir / "bin" / "odocan")
    _run([odocan, "run", "--duration", "5", "--log", "drive.log", "--report", "run.json"], cwd=work)
    analyzed = _run([odocan, "analyze", "drive.log"], cwd=work)
    assert "PASS" in analyzed.stdout
    module = _run([str(python), "-m", "odocan", "--version"], cwd=work)
    assert module.stdout.startswith("odocan ")
    _run([str(python), "-c", "import firmware, odocan.firmware; assert firmware.MINE"], cwd=work)

    (work / "test_external.py").write_text(EXTERNAL_TEST)
    tested = _run([str(python), "-m", "pytest", "-q", "-p", "no:cacheprovider", "test_external.py"],
                  cwd=work)
    assert "1 passed" in tested.stdout
