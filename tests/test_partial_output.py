"""A write that fails part-way (a full disk, a file-size limit) leaves no truncated output.

On a 64 KiB tmpfs, ``odocan analyze drive.log --report r.json`` said ``No space left on device``
(exit 2) and left 4096 bytes of JSON at ``r.json`` (``--mcap``: a truncated MCAP; ``--junit``:
an empty file): a CI step that collects the report reads a broken one, or whatever it makes of
it. The failure is made here without root: RLIMIT_FSIZE with SIGXFSZ ignored turns a write past
the limit into EFBIG, a real OS error at the same place as ENOSPC.
"""

from __future__ import annotations

import io
import subprocess
import sys
from pathlib import Path

import pytest

from tests.limited import run_limited

LIMIT_BYTES = 500  # the report, the JUnit file (760 bytes) and the MCAP of a 2 s drive are larger


@pytest.fixture(scope="module")
def drive_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 2 s kobuki drive's candump log (written without a limit; warms the DBC plan cache)."""
    log = tmp_path_factory.mktemp("partial") / "drive.log"
    subprocess.run(
        [sys.executable, "-m", "odocan", "run", "--robot", "kobuki", "--duration", "2",
         "--log", str(log)],
        capture_output=True, text=True, timeout=300, check=True,
    )
    return log


@pytest.mark.parametrize("option", ["--report", "--junit", "--mcap"])
def test_failed_output_leaves_no_partial_file(
    drive_log: Path, tmp_path: Path, option: str
) -> None:
    """Past the size limit: the verdict printed, one line naming the path and saying the partial
    file was removed, exit 2, and no file at the path."""
    out = tmp_path / {"--report": "r.json", "--junit": "j.xml", "--mcap": "m.mcap"}[option]
    done = run_limited(["analyze", str(drive_log), "--robot", "kobuki", option, str(out)],
                       file_bytes=LIMIT_BYTES)
    print(done.stdout[-300:], done.stderr)
    assert "PASS" in done.stdout
    assert done.returncode == 2
    lines = done.stderr.splitlines()
    assert len(lines) == 1
    assert lines[0].startswith(f"error: {option} {out}: ")
    assert lines[0].endswith("; the partial file removed")
    assert not out.exists()


def test_failed_open_keeps_the_file_there(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A write refused at open (EACCES, nothing written) removes nothing: only a file this write
    truncated is removed, never a user's earlier report."""
    import errno

    from odocan.host.outputs import OutputError, write_text

    keep = tmp_path / "old.json"
    keep.write_text("{}\n")

    def refused(self: Path, *args: object, **kwargs: object) -> None:
        raise PermissionError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(Path, "open", refused)
    with pytest.raises(OutputError) as raised:
        write_text(keep, "{\"new\": 1}\n", "--report")
    monkeypatch.undo()
    assert str(raised.value) == f"--report {keep}: Permission denied"
    assert keep.read_text() == "{}\n"


def test_a_device_is_never_removed(tmp_path: Path) -> None:
    """ENOSPC on /dev/full: the one line as before, and /dev/full stays a device."""
    from odocan.host.outputs import OutputError, write_text

    full = Path("/dev/full")
    if not full.exists():
        pytest.skip("no /dev/full")
    with pytest.raises(OutputError) as raised:
        write_text(full, "x" * 10000, "--report")
    assert str(raised.value) == "--report /dev/full: No space left on device"
    assert full.is_char_device()


def test_a_symlink_is_never_removed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``--report /dev/stdout > out.txt`` reaches out.txt through a symlink: a failed write there
    removes neither the link nor the file the shell redirected into (it holds the summary)."""
    import errno
    import io

    from odocan.host.outputs import OutputError, write_text

    target = tmp_path / "out.txt"
    target.write_text("the summary\n")
    link = tmp_path / "stdout"
    link.symlink_to(target)

    class _Full(io.StringIO):
        def write(self, text: str) -> int:
            raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(Path, "open", lambda self, *a, **k: _Full())
    with pytest.raises(OutputError) as raised:
        write_text(link, "{}\n", "--report")
    monkeypatch.undo()
    assert str(raised.value) == f"--report {link}: No space left on device"
    assert link.is_symlink()
    assert target.read_text() == "the summary\n"


def _vectors(out: Path, *options: str, limited: bool) -> subprocess.CompletedProcess[str]:
    return run_limited(["vectors", *options, "--out", str(out)],
                       file_bytes=LIMIT_BYTES if limited else None)


def test_vectors_past_the_limit_leave_no_partial_file(tmp_path: Path) -> None:
    """``odocan vectors --out DIR`` on a full disk left a truncated vectors.json there: now
    one line naming DIR, exit 2, and not a byte of the set (nor a temporary file)."""
    out = tmp_path / "vectors"
    done = _vectors(out, "--duration", "0.1", limited=True)
    assert done.returncode == 2, done.stderr
    assert [p.name for p in out.iterdir()] == []
    lines = done.stderr.splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"error: --out {out}: ")
    assert lines[0].endswith("; the partial files removed")


def test_vectors_past_the_limit_keep_the_older_set(tmp_path: Path) -> None:
    """A set already in DIR stays whole, byte for byte (not a new JSON beside old CSVs), and
    still checks against the firmware."""
    out = tmp_path / "vectors"
    assert _vectors(out, "--duration", "0.1", limited=False).returncode == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    done = _vectors(out, "--duration", "0.2", "--seed", "7", limited=True)
    assert done.returncode == 2, done.stderr
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert _vectors(out, "--check", limited=False).returncode == 0


@pytest.mark.parametrize(("option", "argv"), [
    ("--latency-plot", ["run", "--firmware", "python", "--duration", "1", "-b", "500000"]),
    ("--plot", ["umbmark", "--runs", "1", "--side", "0.2"]),
])
def test_a_plot_past_the_limit_leaves_no_partial_image(
    tmp_path: Path, option: str, argv: list[str]
) -> None:
    """``run --latency-plot`` and the experiments' ``--plot`` (umbmark, calibrate) said the
    error but left the image cut at the limit: removed now, as ``--plot`` of run and analyze."""
    out = tmp_path / "plot.png"
    done = run_limited([*argv, option, str(out)], file_bytes=LIMIT_BYTES)
    assert done.returncode == 2, done.stderr
    assert not out.exists()
    assert done.stderr.splitlines() == [
        f"error: {option} {out}: File too large; the partial file removed"]


def test_parquet_past_the_limit_keeps_the_older_tables(drive_log: Path, tmp_path: Path) -> None:
    """``--parquet DIR`` is a set of tables, as vectors': on a full disk none of them is cut
    at the limit or lost (an older set there stays byte for byte), the error in one line."""
    out = tmp_path / "tables"
    argv = ["analyze", str(drive_log), "--robot", "kobuki", "--parquet", str(out)]
    subprocess.run([sys.executable, "-m", "odocan", *argv], capture_output=True, timeout=300,
                   check=True)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    done = run_limited(argv, file_bytes=LIMIT_BYTES)
    assert "PASS" in done.stdout
    assert done.returncode == 2, done.stderr
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    lines = done.stderr.splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"error: --parquet {out}: ")
    assert lines[0].endswith("; the partial files removed")


def test_a_signal_mid_write_leaves_no_partial_report(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """SIGTERM (``Terminated``) while the report is being written: before, the exception went
    through and left the report cut where it landed; now the part is removed, the interruption
    goes on to the CLI (its one line, exit 143)."""
    from odocan.host.outputs import write_text
    from odocan.sim.exceptions import Terminated

    report = tmp_path / "r.json"
    signal_mid_write(monkeypatch)
    with pytest.raises(Terminated):
        write_text(report, "{" + " " * 1000 + "}\n", "--report")
    monkeypatch.undo()
    assert not report.exists()


def signal_mid_write(monkeypatch: pytest.MonkeyPatch) -> None:
    """``Path.open`` gives files whose first write puts 100 characters, then raises
    ``Terminated``: a signal in the middle of writing an output."""
    from odocan.sim.exceptions import Terminated

    opened = Path.open

    class _Signalled(io.StringIO):
        def __init__(self, real: io.TextIOBase) -> None:
            super().__init__()
            self.real = real

        def write(self, text: str) -> int:
            self.real.write(text[:100])
            self.real.flush()
            raise Terminated

        def close(self) -> None:
            self.real.close()

    def signalled(self: Path, *args: object, **kwargs: object) -> _Signalled:
        return _Signalled(opened(self, "w", encoding="utf-8"))

    monkeypatch.setattr(Path, "open", signalled)
