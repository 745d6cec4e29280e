"""A ``.blf`` with a corrupt object header is said to be corrupt, where (issue #11).

python-can's ``BLFReader`` takes frames only from log containers of a compression it knows and
skips any other object (an unknown compression with a bare ``logging`` line), so a ``.blf``
whose first container header was corrupt read "error: ...: empty log (not a single CAN frame)",
and a broken object signature "cannot read frame 1: BLFParseError: BLFParseError". Now: one
line naming the path, "corrupt BLF" and the byte, exit 2; a later container skipped is a
warning with the frames read. The headers are edited at the offsets of the BLF format (file
header 144 bytes; an object header "LOBJ", u16 size, u16 version, u32 size, u32 type; a
container's u16 compression method after it)."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest

from odocan.host.cli.app import main
from odocan.host.io.logs import read_log

FIRST_OBJECT_B = 144  # the file header's size in our recorder's (python-can's) files
EDITS = {  # what is broken: (offset from the object, new bytes, the error's words)
    "signature": (0, b"XXXX", "no object signature (LOBJ)"),
    "type": (12, struct.pack("<L", 255), "object type 255, not a log container (10)"),
    "method": (16, struct.pack("<H", 7), "compression method 7, unknown (0 none, 2 zlib)"),
}


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An 8 s drive's ``.blf``: two containers."""
    path = tmp_path_factory.mktemp("blf") / "drive.blf"
    assert main(["run", "--duration", "8", "--log", str(path)]) == 0
    return path


def _objects(data: bytes) -> list[int]:
    """The byte offsets of the top-level objects (walked by their sizes, as the format says)."""
    offsets, pos = [], FIRST_OBJECT_B
    while pos + 16 <= len(data):
        offsets.append(pos)
        size = struct.unpack_from("<L", data, pos + 8)[0]
        pos += size + size % 4
    return offsets


def _edited(drive: Path, tmp_path: Path, edit: str, object_index: int) -> tuple[Path, int]:
    data = bytearray(drive.read_bytes())
    where = _objects(bytes(data))[object_index]
    offset, new, _ = EDITS[edit]
    data[where + offset: where + offset + len(new)] = new
    path = tmp_path / f"{edit}.blf"
    path.write_bytes(bytes(data))
    return path, where


@pytest.mark.parametrize("command", ["analyze", "replay"])
@pytest.mark.parametrize("edit", sorted(EDITS))
def test_a_corrupt_first_container_header_is_said_corrupt(
    drive: Path, tmp_path: Path, edit: str, command: str, capsys: pytest.CaptureFixture[str]
) -> None:
    path, where = _edited(drive, tmp_path, edit, 0)
    capsys.readouterr()
    assert main([command, str(path)]) == 2
    err = capsys.readouterr().err
    assert err == (f"error: {path}: corrupt BLF: object at byte {where}: {EDITS[edit][2]} "
                   "(not a single CAN frame read)\n")


def test_a_later_container_skipped_is_warned(drive: Path, tmp_path: Path) -> None:
    assert len(_objects(drive.read_bytes())) == 2
    whole = len(read_log(drive, warn=pytest.fail))
    path, where = _edited(drive, tmp_path, "type", 1)
    told: list[str] = []
    frames = len(read_log(path, warn=told.append))
    assert 0 < frames < whole
    assert told == [f"{path}: corrupt object at byte {where}: object type 255, not a log "
                    f"container (10): skipped (the frames it held, if any, not read; {frames} "
                    "frames read from the rest)"]
