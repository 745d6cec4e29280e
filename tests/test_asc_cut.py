"""An ``.asc`` cut in the middle of its last frame line (a recorder killed while writing).

Found in a user trial: ``head -c 20000 drive.asc > cut.asc`` ends on ``... 100 Rx d 8 8C 18 13
F3 00 09 F3``: python-can's reader returns that frame with DLC 8 and 7 data bytes, and the log
reader kept it as an 8-byte frame whose last byte nobody sent, without a word (a ``.log`` cut
the same way is skipped with a warning). A frame with fewer data bytes than its DLC is now
skipped and counted in one warning.
"""

from __future__ import annotations

from pathlib import Path

import can

from odocan.host.io.logs import iter_log, read_log


def _asc_cut_in_last_frame(folder: Path) -> Path:
    whole = folder / "whole.asc"
    with can.ASCWriter(whole) as writer:
        for k in range(5):
            writer.on_message_received(can.Message(
                timestamp=0.01 * k, arbitration_id=0x100, is_extended_id=False,
                data=bytes(range(k, k + 8))))
    text = whole.read_text()
    last = [line for line in text.splitlines() if " 100 " in line][-1]  # the last frame line
    cut = folder / "cut.asc"
    cut.write_text(text[: text.index(last) + len(last.rstrip()) - 3] + "\n")  # a byte short
    return cut


def test_a_frame_line_cut_short_is_skipped_with_a_warning(tmp_path: Path) -> None:
    cut = _asc_cut_in_last_frame(tmp_path)
    warnings: list[str] = []
    frames = read_log(cut, warn=warnings.append)
    assert len(frames) == 4
    assert [bytes(frames.data[k][: frames.dlc[k]]) for k in range(4)] == [
        bytes(range(k, k + 8)) for k in range(4)]
    assert len(warnings) == 1, warnings
    assert "1 frame with fewer data bytes than its DLC" in warnings[0]
    streamed: list[str] = []
    assert sum(len(chunk) for chunk in iter_log(cut, chunk_frames=2, warn=streamed.append)) == 4
    assert streamed == warnings


def test_a_last_line_cut_before_its_frame_is_counted(tmp_path: Path) -> None:
    """``head -c`` that ends on `` 1.981000 1  `` (found by the trial): python-can skips the
    stump as an unknown event, so the lost frame went without a word; a timestamped last line
    without its newline is now counted as cut."""
    whole = _asc_cut_in_last_frame(tmp_path).read_text()
    last = [line for line in whole.splitlines() if " 100 " in line][-1]
    stump = tmp_path / "stump.asc"
    stump.write_text(whole[: whole.index(last)] + last[: last.index(" 100 ")])
    warnings: list[str] = []
    assert len(read_log(stump, warn=warnings.append)) == 4
    assert len(warnings) == 1, warnings
    assert "skipped 1 line that is no ASC frame or event" in warnings[0]
