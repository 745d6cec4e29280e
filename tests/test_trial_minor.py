"""Minor defects an outside trial of ``analyze`` and ``replay`` found on a plain square drive
(issue #11's trial 39): a fractional count of poses sent, a huge timestamp leaking a numpy
warning and a 300-digit number, an ``--integrator`` other than the firmware's passing, and a
reversed log refused with a message that did not say what was wrong."""

from __future__ import annotations

import json
import re
import warnings
from pathlib import Path

import can
import cantools
import pytest
from cantools.autosar import compute_profile2_crc
from cantools.database.can import Database

from odocan.sim import contract
from tests.dbc_typed import dbc_attribute
from tests.test_cli_run import run_cli

ENC_COUNTER_LSB = 0x10  # ODOM_POSE_X byte 1: COUNTER low nibble, ENC_COUNTER high nibble


@pytest.fixture(scope="module")
def square(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A correct 3 s square drive (exact integrator, reported by its ODOM_STATUS)."""
    from odocan.host.cli.app import main

    log = tmp_path_factory.mktemp("trial") / "base.log"
    assert main(["run", "--scenario", "square", "--duration", "3", "--log", str(log)]) == 0
    return log


def renamed_x(src: Path, dst: Path, nth: int) -> None:
    """``src`` with the ``nth`` ODOM_POSE_X's ENC_COUNTER raised by one (it names the next
    encoder frame; its ODOM_POSE_Y partner still names the right one), re-signed by cantools."""
    db = cantools.database.load_file(str(contract.DBC_PATH))
    assert isinstance(db, Database)
    target = db.get_message_by_name("ODOM_POSE_X")
    ids = [int(v) for v in dbc_attribute(target, "E2EDataIDs").split(",")]
    k = 0
    with can.Logger(str(dst)) as out:
        for msg in can.LogReader(str(src)):
            if msg.arbitration_id == target.frame_id:
                if k == nth:
                    data = bytearray(msg.data)
                    data[1] = (data[1] + ENC_COUNTER_LSB) & 0xFF
                    crc = compute_profile2_crc(bytes(data), ids[data[1] & 0xF])
                    assert crc is not None
                    data[0] = crc
                    msg.data = data
                k += 1
            out.on_message_received(msg)


def test_a_renamed_pose_half_counts_whole_poses(
    square: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """One X half naming the next encoder frame: its Y half is judged alone, the X half left
    unmatched; the two are one pose sent, not 1.5 (was "judged 150 of 150.5")."""
    tampered = tmp_path / "t.log"
    renamed_x(square, tampered, 50)
    for stream in ("never", "always"):
        report = tmp_path / f"{stream}.json"
        _, out, _ = run_cli(capsys, "analyze", str(tampered), "--stream", stream,
                            "--report", str(report))
        samples = json.loads(report.read_text())["samples"]
        line = next(x for x in out.splitlines() if x.strip().startswith("judged"))
        sent = line.split(" of ")[1].split()[0]
        assert sent.isdigit(), line
        poses = json.loads(report.read_text())["frames"]["ODOM_POSE_X"]
        assert int(sent) == poses, (line, samples)


def test_a_huge_timestamp_is_a_bad_line(
    square: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``(1e300)``: refused as ``(nan)`` is (exit 2, one line naming the line), no numpy
    warning, no 300-digit number."""
    lines = square.read_text().splitlines(keepends=True)
    bad = tmp_path / "huge.log"
    bad.write_text("".join([*lines[:100], "(1e300) vcan0 200#CA4A631F00000030\n", *lines[100:]]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        code, _, err = run_cli(capsys, "analyze", str(bad))
    assert code == 2, err
    assert err.count("\n") == 1, err
    assert ":101: bad timestamp '(1e300)'" in err, err
    assert not re.search(r"[0-9]{20}", err), err


def test_an_integrator_other_than_the_firmwares_fails(
    square: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--integrator euler`` on an exact firmware's log: FAIL (exit 1) naming the mismatch,
    as a wrong ``--robot`` does; analyze whole, streamed and replay alike."""
    for args in (("analyze", "--stream", "never"), ("analyze", "--stream", "always"),
                 ("replay",)):
        code, out, err = run_cli(capsys, args[0], str(square), *args[1:],
                                 "--integrator", "euler")
        assert code == 1, (args, out, err)
        fail = [x for x in out.splitlines() if "integrator mismatch" in x]
        assert fail, (args, out)
        assert "exact" in fail[0], fail
        assert "euler" in fail[0], fail
    code, out, _ = run_cli(capsys, "analyze", str(square), "--integrator", "exact")
    assert code == 0
    assert "mismatch" not in out


def test_a_reversed_log_says_it_runs_backwards(
    square: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``tac LOG``: exit 2 with one line that says the log is not in time order."""
    reversed_log = tmp_path / "rev.log"
    reversed_log.write_text("".join(reversed(square.read_text().splitlines(keepends=True))))
    for stream in ("never", "always"):
        code, _, err = run_cli(capsys, "analyze", str(reversed_log), "--stream", stream)
        assert code == 2, err
        error = [x for x in err.splitlines() if x.startswith("error:")]
        assert len(error) == 1, err
        assert "not in time order" in error[0], err
