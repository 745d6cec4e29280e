"""A frame whose time is no clock's (beyond 1e12 s either side, NaN, infinite) is a bad frame in
every log format ``analyze`` reads, as it is in a candump ``.log`` (``test_trial_minor``,
``test_outside_inputs``): exit 2 and one line naming the file and the frame (an ``.asc``'s
line). Only the candump parser checked it: an ``.asc``, ``.trc``, ``.csv`` or ``.db`` log with a
frame at 5e13 s or NaN s was analysed on.

The logs are written with python-can's own writers (``can.Logger`` by suffix) from a correct
drive's frames, one frame's time replaced. A ``.blf`` cannot hold such a time (python-can's
writer refuses it: its header's date is at most year 9999 and its times unsigned nanoseconds
from it, under 3e11 s); an ``.asc`` line whose time is not a number is no ASC line (skipped
with a warning, as every garbage line is: ``host.io.asc``). A negative time within the bound
(a clock before 1970, a log shifted back) is a clock's time and analysed, in every format.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import can
import pytest

from odocan.host.io.frames import MAX_TIMESTAMP_S, timestamp_fault
from tests.test_cli_run import run_cli

BAD_AT = 100  # the frame (1-based: 101) whose time is replaced


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> list[can.Message]:
    """A correct 1 s square drive's frames."""
    from odocan.host.cli.app import main

    log = tmp_path_factory.mktemp("bound") / "base.log"
    assert main(["run", "--scenario", "square", "--duration", "1", "--log", str(log)]) == 0
    return list(can.LogReader(str(log)))


def _written(frames: list[can.Message], path: Path, bad_s: float) -> Path:
    """``frames`` written by python-can's writer for ``path``'s suffix, frame ``BAD_AT + 1``'s
    time ``bad_s``; the time the reader reads back is checked to be that."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the .db writer's
        with can.Logger(str(path)) as out:
            for k, msg in enumerate(frames):
                out.on_message_received(msg if k != BAD_AT else can.Message(
                    timestamp=bad_s, arbitration_id=msg.arbitration_id, data=msg.data,
                    is_extended_id=msg.is_extended_id))
    read_s = [msg.timestamp for msg in can.LogReader(str(path))][BAD_AT]
    assert read_s is None or timestamp_fault(read_s) is not None, read_s  # as written
    return path


FORMATS = ("asc", "trc", "csv", "db")
ABSURD = {"huge": 5e13, "minus_huge": -5e13, "nan": math.nan, "inf": math.inf}
WRITABLE = [(suffix, name) for suffix in FORMATS for name in ABSURD
            if not (suffix == "asc" and name != "huge")]  # no ASC line: module docstring


@pytest.mark.parametrize(("suffix", "name"), WRITABLE)
@pytest.mark.parametrize("stream", ["never", "always"])
def test_an_absurd_timestamp_is_a_bad_frame_in_every_format(
    drive: list[can.Message], suffix: str, name: str, stream: str, tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    bad = _written(drive, tmp_path / f"bad.{suffix}", ABSURD[name])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no numpy warning leaks
        code, out, err = run_cli(capsys, "analyze", str(bad), "--stream", stream)
    assert code == 2, (out, err)
    assert err.count("\n") == 1, err
    where = f"{bad}:" if suffix == "asc" else f"{bad}: frame {BAD_AT + 1}: "
    assert err.startswith(f"error: {where}"), err
    if suffix == "asc":  # its line: the header's lines before the frames
        line = int(err.split(f"{bad}:")[1].split(":")[0])
        assert float(bad.read_text().splitlines()[line - 1].split()[0]) > MAX_TIMESTAMP_S
    if suffix == "db" and name == "nan":  # python-can's writer stores NaN as NULL
        assert err.endswith(": no timestamp\n"), err
        return
    fault = "not a finite number" if not math.isfinite(ABSURD[name]) \
        else f"beyond {MAX_TIMESTAMP_S:g} s"
    assert f": bad timestamp {ABSURD[name]!r} ({fault}" in err, err


@pytest.mark.parametrize("suffix", ["log", *FORMATS])
def test_a_time_before_1970_within_the_bound_is_read(
    drive: list[can.Message], suffix: str, tmp_path: Path, capsys: pytest.CaptureFixture[str],
) -> None:
    """Every frame 1.7e9 s before 1970: analysed as the drive is (PASS), in every format."""
    shifted = [can.Message(timestamp=msg.timestamp - 1.7e9, arbitration_id=msg.arbitration_id,
                           data=msg.data, is_extended_id=msg.is_extended_id,
                           is_rx=msg.is_rx) for msg in drive]
    path = tmp_path / f"before.{suffix}"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with can.Logger(str(path)) as writer:
            for msg in shifted:
                writer.on_message_received(msg)
    code, out, err = run_cli(capsys, "analyze", str(path))
    assert code == 0, (out, err)
    assert "PASS" in out, out
