"""Bad input found from outside that was taken without a word; each now is one ``error: ...``
line and exit 2, or a warning with a count, and every case here was accepted silently before its
fix: a filter no frame can match, a sender no DBC node is, a negative bitrate, an ambiguous
babble ID, a log whose times go back, garbage lines in an ``.asc``, a ``.blf`` cut short, and a
replay with another integrator than the log's firmware ran."""

from __future__ import annotations

import json
from pathlib import Path

import can
import numpy as np
import pytest

from odocan.host.cli.app import main
from odocan.host.io.logs import iter_log, read_log
from odocan.sim.faultspec import FaultSpec
from tests.test_outside_inputs import _one_error_line


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """One 3 s drive logged as .log, .asc and .blf (the same frames)."""
    out = tmp_path_factory.mktemp("drive")
    logs = {suffix: out / f"drive{suffix}" for suffix in (".log", ".asc", ".blf")}
    for path in logs.values():
        assert main(["run", "--duration", "3", "--log", str(path)]) == 0
    return logs


def test_a_filter_beyond_29_bit_ids_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    err = _one_error_line(capsys, ["monitor", "-i", "virtual", "-c", "refusals",
                                   "--filter", "0x800000000", "--duration", "0.1"])
    assert "--filter 0x800000000: beyond the 29-bit CAN IDs" in err


def test_busload_refuses_a_sender_that_is_no_node(capsys: pytest.CaptureFixture[str]) -> None:
    err = _one_error_line(capsys, ["busload", "--add", "HOG:0x050:8:2:NOBODY"])
    assert "NOBODY is no node of the DBC (HOST, MOTOR_CTRL, ODOM_MCU, SIM)" in err


@pytest.mark.parametrize("command", [["monitor"], ["sim"], ["firmware"], ["bridge"]])
@pytest.mark.parametrize("bitrate", ["-5", "0", "5000000000"])
def test_a_live_bus_bitrate_out_of_range_is_refused(
    command: list[str], bitrate: str, capsys: pytest.CaptureFixture[str]
) -> None:
    err = _one_error_line(capsys, [*command, "-i", "virtual", "-c", "refusals", "-b", bitrate,
                                   "--duration", "0.1"])
    assert f"argument -b/--bitrate: '{bitrate}': a CAN bitrate is 1 .. 1000000 bit/s" in err


@pytest.mark.parametrize("text", ["0x900", "2304"])
def test_a_babble_id_above_0x7ff_written_as_an_11_bit_one_is_refused(
    text: str, capsys: pytest.CaptureFixture[str]
) -> None:
    err = _one_error_line(capsys, ["run", "--duration", "1", "--faults", f"babble=100:{text}"])
    assert f"ID {text} is above 0x7FF, the largest 11-bit ID" in err
    assert "0x00000900" in err


def test_a_29_bit_babble_id_reads_back_from_its_own_text() -> None:
    spec = FaultSpec.parse("babble=100:0x00000900")
    assert spec.babble_id == 0x900
    assert FaultSpec.parse(str(spec)) == spec  # printed with its 8 digits


def _times_going_back(source: Path, target: Path) -> None:
    """``source`` with frame 501's time one second back."""
    lines = source.read_text().splitlines(keepends=True)
    stamp = lines[500].split(")")[0][1:]
    lines[500] = lines[500].replace(stamp, f"{float(stamp) - 1.0:.6f}", 1)
    target.write_text("".join(lines))


def test_a_log_whose_times_go_back_is_warned_with_a_count(
    drive: dict[str, Path], tmp_path: Path
) -> None:
    path = tmp_path / "back.log"
    _times_going_back(drive[".log"], path)
    told: list[str] = []
    frames = read_log(path, warn=told.append)
    assert len(told) == 1, told
    assert (f"{path}: 1 frame of {len(frames)} earlier than the latest frame before them "
            "(first: frame 501, ") in told[0]
    back_ms = float(told[0].split(" ms back from ")[0].rsplit(" ", 1)[-1])  # how far, said
    assert 989 <= back_ms <= 1000, told[0]  # its second back, less the spacing (<= 11 ms)
    chunked: list[str] = []
    assert sum(len(c) for c in iter_log(path, chunk_frames=7, warn=chunked.append)) == len(frames)
    assert chunked == told
    clean: list[str] = []
    read_log(drive[".log"], warn=clean.append)
    assert clean == []


def _stamps_back(source: Path, target: Path, back_s: float, every: int) -> int:
    """``source`` with every ``every``-th frame stamped ``back_s`` before the frame before it
    (what a recorder reading two senders' frames stamps); returns how many."""
    lines = source.read_text().splitlines(keepends=True)
    moved = 0
    for k in range(every, len(lines), every):
        before = float(lines[k - 1].split(")")[0][1:])
        stamp = lines[k].split(")")[0][1:]
        lines[k] = lines[k].replace(stamp, f"{before - back_s:.6f}", 1)
        moved += 1
    target.write_text("".join(lines))
    return moved


def test_a_recorders_us_inversions_are_not_warned_a_ms_one_is(
    drive: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The trial (issue #11, rule 6): a recording with ~3 us inversions between senders made
    analyze warn "13 frames earlier than the frame before ... the log's duration may be wrong":
    a recorder's stamping, which can change no verdict nor duration, is not warned; an
    inversion beyond 1 ms is."""
    path = tmp_path / "stamped.log"
    assert _stamps_back(drive[".log"], path, 3e-6, 97) > 10
    told: list[str] = []
    read_log(path, warn=told.append)
    assert told == []
    capsys.readouterr()
    assert main(["analyze", str(path)]) == 0
    assert "earlier than the latest frame before" not in capsys.readouterr().err
    moved = _stamps_back(drive[".log"], path, 0.0015, 97)
    read_log(path, warn=told.append)
    assert len(told) == 1, told
    assert told[0].startswith(
        f"{path}: {moved} frames of {len(read_log(drive['.log']))} earlier than the latest "
        "frame before them"), told


def test_analyze_says_once_that_times_go_back(
    drive: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "back.log"
    _times_going_back(drive[".log"], path)
    main(["analyze", str(path), "--stream", "always"])
    err = capsys.readouterr().err
    assert err.count("earlier than the latest frame before") == 1, err


def test_garbage_lines_in_an_asc_are_skipped_with_a_count(
    drive: dict[str, Path], tmp_path: Path
) -> None:
    lines = drive[".asc"].read_text().splitlines(keepends=True)
    lines.insert(300, "garbage here !!\n")  # python-can skipped it without a word
    lines.insert(600, "   0.500000 1  1X0             Rx   d 8 zz zz 00 00 00 00 00 00\n")
    path = tmp_path / "garbage.asc"
    path.write_text("".join(lines))  # the second one stopped the whole read
    told: list[str] = []
    frames = read_log(path, warn=told.append)
    assert told == [f"{path}: skipped 2 lines that are no ASC frame or event (first: line 301)"]
    clean = read_log(drive[".asc"])
    assert np.array_equal(frames.timestamp_s, clean.timestamp_s)
    assert np.array_equal(frames.data, clean.data)
    chunked: list[str] = []
    assert sum(len(c) for c in iter_log(path, chunk_frames=64, warn=chunked.append)) == len(clean)
    assert chunked == told


def test_a_blf_cut_short_is_warned(drive: dict[str, Path], tmp_path: Path) -> None:
    data = drive[".blf"].read_bytes()
    path = tmp_path / "cut.blf"
    path.write_bytes(data[: len(data) * 2 // 3])
    told: list[str] = []
    frames = read_log(path, warn=told.append)
    assert 0 < len(frames) < len(read_log(drive[".blf"]))
    assert len(told) == 1, told
    assert told[0].startswith(f"{path}: cut short: {path.stat().st_size} of the {len(data)} "
                              "bytes its header gives")
    whole: list[str] = []
    read_log(drive[".blf"], warn=whole.append)
    assert whole == []
    assert can.BLFReader(drive[".blf"]).file_size == len(data)


@pytest.mark.parametrize("command", ["analyze", "replay"])
def test_a_corrupt_blf_is_one_clean_error_line(
    drive: dict[str, Path], tmp_path: Path, command: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """A ``.blf`` whose compressed container is corrupt read "error: ...: cannot read frame 1:
    error: Error -3 while decompressing data: ..." (two "error:", zlib's class name taken for
    the cause): one line naming the path and the cause (issue #11, rule 6)."""
    data = bytearray(drive[".blf"].read_bytes())
    for i in range(400, 600):
        data[i] ^= 0x55
    path = tmp_path / "corrupt.blf"
    path.write_bytes(bytes(data))
    err = _one_error_line(capsys, [command, str(path)])
    assert err.lower().count("error") == 2, err  # "error: " and "zlib error", no other
    assert err.startswith(f"error: {path}: cannot read frame 1: zlib error -3 (compressed data "
                          "corrupt): "), err


def test_replay_names_an_integrator_other_than_the_logs(
    drive: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    report = tmp_path / "replay.json"
    main(["replay", str(drive[".log"]), "--integrator", "rk2", "--report", str(report)])
    err = capsys.readouterr().err
    assert (f"warning: integrator mismatch: {drive['.log']}'s ODOM_STATUS reports exact, "
            "--integrator asks rk2") in err
    assert json.loads(report.read_text())["integrator"] == "rk2"
    main(["replay", str(drive[".log"]), "--integrator", "exact"])
    assert "mismatch" not in capsys.readouterr().err
