"""A ``--dbc`` lacking a signal odocan's judges read: one line, exit 2, naming it.

An outside trial (a user's own DBC): ``odocan analyze ok.log --dbc x.dbc`` with ODOM_POSE_Y's
TURNS dropped ended in ``KeyError: 'TURNS'``, exit 1 -- the documented "check failed" code, so
CI read a broken DBC as a FAIL of the firmware; so did X, HEADING, Y, the twist's signals,
ENC_E2E_OK and SIM_TRUTH's ENC_COUNTER (X and HEADING at import: the named DBC had become the
process's, ``host.cli.dbcfirst``). Every signal of every message of odocan's DBC, dropped in
turn from a copy (its SG_, CM_ and VAL_ lines): the command refuses it in one line.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import cantools
import pytest

from odocan.host.cli.app import main
from odocan.sim import SHIPPED_DBC
from tests.test_cli_run import assert_usage_error

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = cantools.database.load_file(SHIPPED_DBC)
assert isinstance(SHIPPED, cantools.database.can.Database)
SIGNALS = [(m.frame_id, m.name, s.name) for m in SHIPPED.messages for s in m.signals
           if not s.is_multiplexer]


def _without(frame_id: int, signal: str, path: Path) -> Path:
    """odocan's DBC without ``signal`` of message ``frame_id``: its SG_, CM_ SG_ and VAL_ lines."""
    kept, message = [], None
    for line in SHIPPED_DBC.read_text().splitlines(keepends=True):
        if line.startswith("BO_ "):
            message = int(line.split()[1])
        elif not line.strip():
            message = None
        ours = message == frame_id and re.match(rf"\s*SG_ {signal}\b", line)
        if ours or line.startswith((f"CM_ SG_ {frame_id} {signal} ", f"VAL_ {frame_id} {signal} ")):
            continue
        kept.append(line)
    path.write_text("".join(kept))
    return path


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    log = tmp_path_factory.mktemp("lacking") / "drive.asc"
    assert main(["run", "--duration", "0.5", "--log", str(log)]) == 0
    return log


@pytest.mark.parametrize(("frame_id", "message", "signal"), SIGNALS,
                         ids=[f"{m}.{s}" for _, m, s in SIGNALS])
def test_a_dbc_lacking_a_signal_is_refused_naming_it(
    frame_id: int, message: str, signal: str, drive: Path, tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    dbc = _without(frame_id, signal, tmp_path / "lacking.dbc")
    capsys.readouterr()
    assert_usage_error(capsys, main(["analyze", str(drive), "--dbc", str(dbc)]),
                       signal)  # "--dbc PATH: MESSAGE lacks SIGNAL", or the DBC fact it holds


@pytest.mark.parametrize("signal", ["X", "HEADING"])
def test_a_dbc_read_at_import_is_refused_too(signal: str, drive: Path, tmp_path: Path) -> None:
    """A fresh process: the named DBC was followed (made the process's) before, and a judge
    read the signal by name as it was imported: a traceback, exit 1."""
    dbc = _without(512, signal, tmp_path / "lacking.dbc")
    done = subprocess.run([sys.executable, "-m", "odocan", "analyze", str(drive), "--dbc",
                           str(dbc)], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert (done.returncode, done.stdout) == (2, ""), done.stderr
    assert done.stderr.splitlines() == [
        f"error: --dbc {dbc}: ODOM_POSE_X lacks {signal}, which odocan's judges read (its DBC: "
        f"{SHIPPED_DBC})"]
