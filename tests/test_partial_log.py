"""A candump log cut mid-line (a killed recorder) is read without its partial last line, with a
warning that counts it; a malformed line anywhere else is still refused."""

from __future__ import annotations

from pathlib import Path

import pytest

from odocan.host.io.logs import LogFormatError, read_log

LINES = [
    "(0.000000) vcan0 100#8F00000000000000\n",
    "(0.001000) vcan0 200#FC00000000000000\n",
    "(0.010000) vcan0 100#4101FEFF00FFFF00\n",
]


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "cut.log"
    path.write_text(text)
    return path


@pytest.mark.parametrize("cut", [5, 17, 22, 25, 31])  # in the stamp, channel, ID, data
def test_a_line_cut_mid_way_is_skipped_with_a_counting_warning(tmp_path: Path, cut: int) -> None:
    warnings: list[str] = []
    path = write(tmp_path, "".join(LINES) + LINES[2][:cut])
    frames = read_log(path, warn=warnings.append)
    assert len(frames) == 3
    assert frames.data[2].tobytes().hex() == "4101feff00ffff00"
    assert warnings == [
        f"{path}: skipped 1 partial line at the end (line 4, cut mid-line: a recorder killed "
        "while writing?)"
    ]


def test_the_warning_goes_to_stderr(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = write(tmp_path, "".join(LINES) + "(0.0200")
    assert len(read_log(path)) == 3
    err = capsys.readouterr().err
    assert err.startswith("warning: ")
    assert "skipped 1 partial line" in err
    assert err.count("\n") == 1


def test_a_complete_last_line_without_newline_is_kept(tmp_path: Path) -> None:
    warnings: list[str] = []
    frames = read_log(write(tmp_path, "".join(LINES)[:-1]), warn=warnings.append)
    assert len(frames) == 3
    assert warnings == []


def test_a_bad_line_before_the_end_is_still_refused(tmp_path: Path) -> None:
    with pytest.raises(LogFormatError, match=r"cut\.log:2: "):
        read_log(write(tmp_path, LINES[0] + LINES[1][:12] + "\n" + LINES[2]))
    with pytest.raises(LogFormatError, match=r"cut\.log:3: "):  # the last line, with its newline
        read_log(write(tmp_path, LINES[0] + LINES[1] + LINES[2][:12] + "\n"))
