"""``--log``'s writer (``host.io.recording.Recording``): a batch of queued frames written as
python-can's own writer writes them, frame by frame, from the ``Message`` each would be.

The candump and ASC paths format their lines themselves (no ``Message`` built); python-can's
``CanutilsLogWriter`` (``ASCWriter``) fed the ``Message`` ``recv`` would give is the reference,
byte for byte (an ASC log's first line, the date it was opened, aside):
for random batches (stamps before the log's first, extended, remote, error and FD frames
among the tuples) and for the rig's golden logs (``tests.test_rig.GOLDEN_LOGS``, whose hashes
were made by python-can's writer on python-can's ``virtual`` bus).
"""

from __future__ import annotations

import dataclasses
import hashlib
from pathlib import Path

import can
import pytest
from can.io.asc import ASCWriter
from can.io.canutils import CanutilsLogWriter
from hypothesis import given, settings
from hypothesis import strategies as st

from odocan.host.io.recording import Recording
from odocan.sim.framebatch import Received
from odocan.sim.rig import LockstepRig
from odocan.sim.transport import data_frame
from tests.test_rig import GOLDEN_LOGS

_stamps = st.floats(0.0, 1e6, allow_nan=False)
_tuples = st.tuples(_stamps, st.integers(0, 0x7FF), st.binary(max_size=8))
_messages = st.builds(
    lambda stamp, can_id, extended, data, kind: can.Message(
        timestamp=stamp, arbitration_id=can_id if extended else can_id & 0x7FF,
        is_extended_id=extended, data=b"" if kind == "remote" else data,
        is_remote_frame=kind == "remote", is_error_frame=kind == "error",
        is_fd=kind == "fd", bitrate_switch=kind == "fd", channel="vcan0", is_rx=kind != "tx",
    ),
    _stamps, st.integers(0, 0x1FFFFFFF), st.booleans(), st.binary(max_size=8),
    st.sampled_from(["data", "remote", "error", "fd", "tx"]),
)


def _message(frame: Received, channel: str) -> can.Message:
    """What the ``odocan`` handle's ``recv`` gives for a queued frame (``as_message``)."""
    if not isinstance(frame, tuple):
        return frame
    msg = data_frame(*frame)
    msg.channel = channel
    return msg


def _by_python_can(path: Path, batches: list[list[Received]], channel: str) -> bytes:
    writer = can.Logger(path)
    for batch in batches:
        for frame in batch:
            writer.on_message_received(_message(frame, channel))
    writer.stop()
    return path.read_bytes()


def _by_recording(path: Path, batches: list[list[Received]], channel: str) -> bytes:
    recording = Recording(can.Logger(path), channel)
    for batch in batches:
        recording.on_frames(batch)
    recording.stop()
    assert recording.frames == sum(map(len, batches))
    return path.read_bytes()


def _same_bytes(ours: bytes, theirs: bytes, suffix: str) -> bool:
    """The logs' bytes alike: an ASC log's after its first line (``date`` of its opening)."""
    if suffix == ".asc":
        ours, theirs = ours.split(b"\n", 1)[1], theirs.split(b"\n", 1)[1]
    return ours == theirs


@settings(max_examples=60, deadline=None)
@given(batches=st.lists(st.lists(st.one_of(_tuples, _messages), max_size=12), max_size=6),
       channel=st.sampled_from(["vcan0", "odocan-replay-3", "0", "rig"]),
       suffix=st.sampled_from([".log", ".asc"]))
def test_a_candump_or_asc_log_is_python_cans_byte_for_byte(
    tmp_path_factory: pytest.TempPathFactory, batches: list[list[Received]], channel: str,
    suffix: str,
) -> None:
    folder = tmp_path_factory.mktemp("recording")
    ours = _by_recording(folder / f"ours{suffix}", batches, channel)
    theirs = _by_python_can(folder / f"python-can{suffix}", batches, channel)
    assert _same_bytes(ours, theirs, suffix)


def test_an_asc_log_follows_the_writers_own_templates_when_they_change(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Another python-can's ``ASCWriter`` templates (not the ones the f-string copies): used."""
    monkeypatch.setattr(ASCWriter, "FORMAT_EVENT", "{timestamp: 12.6f}  {message}\n")
    batches: list[list[Received]] = [[(0.5, 0x100, b"\x01\x02"), (0.25, 0x7FF, b"")],
                                     [(1.0, 0x110, bytes(range(8)))]]
    ours = _by_recording(tmp_path / "ours.asc", batches, "vcan0")
    theirs = _by_python_can(tmp_path / "python-can.asc", batches, "vcan0")
    assert b"    0.500000  1  110" in ours  # the changed event template
    assert _same_bytes(ours, theirs, ".asc")


def _read(path: Path) -> list[tuple[float, int, bytes, bool]]:
    with can.LogReader(path) as reader:
        return [(m.timestamp, m.arbitration_id, bytes(m.data), m.is_rx) for m in reader]


@pytest.mark.parametrize("suffix", [".asc", ".blf"])
def test_every_format_gets_the_messages_recv_would_give(tmp_path: Path, suffix: str) -> None:
    batches: list[list[Received]] = [[(0.5, 0x100, b"\x01\x02"), (0.75, 0x7FF, b"")],
                                     [(1.0, 0x110, bytes(range(8)))]]
    ours, theirs = tmp_path / f"ours{suffix}", tmp_path / f"python-can{suffix}"
    _by_recording(ours, batches, "vcan0")
    _by_python_can(theirs, batches, "vcan0")
    assert len(_read(ours)) == 3
    assert _read(ours) == _read(theirs)


@pytest.mark.parametrize("name", sorted(GOLDEN_LOGS))
def test_the_rigs_golden_logs_through_the_recording(tmp_path: Path, name: str) -> None:
    """The CLI's path (``odocan run --log``): the rig hands the recording its batches."""
    config, sha256 = GOLDEN_LOGS[name]
    config = dataclasses.replace(config, transport="odocan")
    path = tmp_path / "run.log"
    with LockstepRig(config, [Recording(can.Logger(path), config.channel)]) as rig:
        rig.run(20.0)
    assert hashlib.sha256(path.read_bytes()).hexdigest() == sha256


class _FillingDisk:
    """A file whose second write fails, as a disk filling up (every other call the file's)."""

    def __init__(self, file: object) -> None:
        self.file, self.writes = file, 0

    def write(self, text: str) -> int:
        self.writes += 1
        if self.writes == 2:
            raise OSError(28, "No space left on device")
        return int(self.file.write(text))  # type: ignore[attr-defined]

    def __getattr__(self, name: str) -> object:
        return getattr(self.file, name)


def test_a_full_disk_stops_the_recording_and_names_the_frames_written(tmp_path: Path) -> None:
    writer = CanutilsLogWriter(tmp_path / "full.log")
    disk = _FillingDisk(writer.file)
    writer.file = disk  # type: ignore[assignment]
    recording = Recording(writer)
    for _ in range(3):
        recording.on_frames([(0.0, 0x100, b"\x00"), (0.01, 0x101, b"\x01")])
    with pytest.raises(OSError, match=r"No space left on device \(recording stopped after 2 "):
        recording.stop()
    assert disk.writes == 2  # nothing more after the failure
