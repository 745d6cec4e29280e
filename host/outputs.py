"""Output paths (``--report``, ``--log``, ``--plot``, ``--out``) checked before the work starts.

A path is writable when it is a regular file (or none yet) in an existing directory that this
process may write, or ``/dev/null``. Anything else -- a missing directory, a directory, a
device such as ``/dev/full`` or a terminal, a read-only file -- is refused at once with the
option and the path named, so an hour of simulation is never lost to a report that cannot be
written. A write that still fails at the end names its path too, and leaves no part of it:
a file is written beside its path and renamed onto it when whole (``replaced``), so an older
file there survives a full disk or a Ctrl-C mid-write.

The check opens the path for real (an existing file for appending, without truncating it; a new
one created and removed at once), because permission bits do not answer it: as root
``os.access`` says yes to ``/proc/x.json`` and to a read-only ``/proc`` or ``/sys`` file, and
``odocan run --report /proc/x.json`` drove the whole run, printed PASS, then failed.

``-`` as the path of ``--report`` or ``--junit`` is standard output, as Unix tools take it
(``odocan analyze drive.log --report - | jq .passed``): the command's own text (the summary, its
hints) then goes to stderr for the command's length (``outputs_on_stdout``), so stdout holds the
output alone.

It lives at host/ level, below every room, so io/ and judge/ use ``OutputError`` without
importing report/.
"""

from __future__ import annotations

import os
import stat
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager, redirect_stdout
from pathlib import Path
from typing import TextIO

from odocan.sim.exceptions import ConfigurationError, OdocanError

STDOUT_NAME = "-"  # an output option's path for standard output
STDOUT_OPTIONS = ("report", "junit")  # the text outputs that take ``-`` (their args names)
_stdout: TextIO | None = None  # standard output while the command's own text goes to stderr


class OutputError(OdocanError):
    """An output could not be written (the path and the reason in one line)."""


def is_stdout(path: Path | None) -> bool:
    """Whether an output option's ``path`` is ``-``: standard output."""
    return path is not None and str(path) == STDOUT_NAME


@contextmanager
def outputs_on_stdout(args: object) -> Iterator[None]:
    """Inside, when one of ``args``' text outputs (``STDOUT_OPTIONS``) is ``-``, what the
    command prints goes to stderr and ``write_text`` writes that output to standard output
    (the module docstring); else nothing changes."""
    global _stdout
    if not any(is_stdout(getattr(args, name, None)) for name in STDOUT_OPTIONS):
        yield
        return
    before, _stdout = _stdout, sys.stdout
    try:
        with redirect_stdout(sys.stderr):
            yield
    finally:
        _stdout = before


def check_writable(path: Path | None, option: str) -> None:
    """Refuse ``path`` unless a file can be created or replaced there (see the module)."""
    if path is None or str(path) == os.devnull or is_stdout(path):
        return
    where = f"{option} {path}"
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        mode = None
    except OSError as exc:  # e.g. /proc/x/f.json: ENOENT above, ENOTDIR, EACCES here
        raise ConfigurationError(f"{where}: {exc.strerror or exc}") from None
    if mode is not None:
        if stat.S_ISDIR(mode):
            raise ConfigurationError(f"{where}: is a directory")
        if not stat.S_ISREG(mode):
            raise ConfigurationError(f"{where}: not a regular file (a device, pipe or socket)")
        _probe(path, os.O_WRONLY | os.O_APPEND, where)
        return
    target = Path(os.path.realpath(path))  # a dangling symlink: the file it will create
    parent = target.parent
    if not parent.is_dir():
        raise ConfigurationError(f"{where}: directory {parent} does not exist")
    _probe(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL, where)
    target.unlink(missing_ok=True)


def check_writable_dir(directory: Path, option: str, shown: Path | None = None) -> None:
    """Refuse ``directory`` unless it exists and a file can be created in it (a probe file,
    removed at once); the error names ``shown`` (default: the directory) after the option."""
    where = f"{option} {shown if shown is not None else directory}"
    if not directory.is_dir():
        raise ConfigurationError(f"{where}: directory {directory} does not exist")
    try:
        with tempfile.TemporaryFile(dir=directory):
            pass
    except OSError as exc:
        raise ConfigurationError(f"{where}: directory {directory}: {exc.strerror or exc}") from None


def _probe(path: Path, flags: int, where: str) -> None:
    """Open ``path`` with ``flags`` and close it; an OSError becomes one line naming it."""
    try:
        os.close(os.open(path, flags, 0o666))
    except OSError as exc:
        raise ConfigurationError(f"{where}: {exc.strerror or exc}") from None


def write_text(path: Path, text: str, option: str) -> None:
    """Write ``text`` to ``path`` in full or not at all (``replaced``: an older file there stays
    whole when the write fails part-way, on a full disk or a signal); an I/O error becomes one
    ``OutputError`` naming the path. ``-``: standard output (``outputs_on_stdout``)."""
    if is_stdout(path):
        out = _stdout or sys.stdout
        out.write(text)
        out.flush()
        return
    with replaced(path, option) as target:
        try:
            handle = target.open("w", encoding="utf-8")
        except OSError as exc:  # nothing written: a file already there stays as it was
            raise OutputError(f"{option} {path}: {exc.strerror or exc}") from None
        with handle:
            handle.write(text)


@contextmanager
def replaced(path: Path, option: str) -> Iterator[Path]:
    """One output file written in full or not at all: yields the path the block writes.

    A regular file (or none yet) is written to a temporary file beside it (``_new_temp``) and
    renamed onto ``path`` once the block ends: a full disk or a signal part-way (Ctrl-C while
    ``--report`` is written) removes the temporary file and leaves an older ``path`` whole --
    it used to be cut, then removed: a CI step lost last night's report with tonight's. An
    older file's permission bits are kept. An ``OSError`` in the block becomes one
    ``OutputError``: ``option path: reason; the partial file removed`` (and ``, the one there
    before kept`` when there was one). A path that is not a plain file (``/dev/full``,
    ``/dev/stdout``, a symlink, a pipe) or a directory where no file can be created (a
    read-only one holding a writable file) is written in place, as before (``output_failed``)."""
    old = _regular_or_none(path)
    temp = None if old is False else _temp_or_none(path)
    if temp is None:
        try:
            yield path
        except OSError as exc:
            raise output_failed(option, path, exc.strerror or str(exc)) from None
        except KeyboardInterrupt:  # Ctrl-C, SIGTERM mid-write: no half report left for a CI step
            output_failed(option, path, "interrupted")
            raise
        return
    try:
        yield temp
        if isinstance(old, os.stat_result):
            os.chmod(temp, stat.S_IMODE(old.st_mode))
        os.replace(temp, path)
    except BaseException as exc:
        temp.unlink(missing_ok=True)
        if isinstance(exc, OSError):
            kept = "" if old is None else ", the one there before kept"
            reason = f"{exc.strerror or exc}; the partial file removed{kept}"
            raise OutputError(f"{option} {path}: {reason}") from None
        raise


def _regular_or_none(path: Path) -> os.stat_result | bool | None:
    """``path``'s stat when it is a regular file (not through a symlink), None when there is no
    file, False for anything else (written in place by ``replaced``)."""
    try:
        found = os.lstat(path)
    except FileNotFoundError:
        return None
    except OSError:
        return False
    return found if stat.S_ISREG(found.st_mode) else False


def _temp_or_none(path: Path) -> Path | None:
    """``_new_temp(path)``, or None where none can be made (a read-only directory)."""
    try:
        return _new_temp(path)
    except OSError:
        return None


def output_failed(option: str, path: Path, reason: str) -> OutputError:
    """The ``OutputError`` for a write to ``path`` that failed part-way (ENOSPC, EFBIG, EIO),
    after removing the partial file it left: a regular file named as itself only (``/dev/full``,
    a pipe, a symlink such as ``/dev/stdout`` to a file the shell redirected into: never
    removed), and the line says so."""
    try:
        if stat.S_ISREG(os.lstat(path).st_mode):
            os.unlink(path)
            reason += "; the partial file removed"
    except OSError:
        pass  # gone already, or not removable: the line names the path either way
    return OutputError(f"{option} {path}: {reason}")


@contextmanager
def replaced_together(paths: list[Path], option: str, shown: Path) -> Iterator[list[Path]]:
    """Files written in full or not at all, as one set (``odocan vectors``' JSON and CSVs).

    Yields a temporary path beside each of ``paths`` (hidden, in the same directory) for the
    block to write; after it, each is renamed onto its path, so an older file there is replaced
    only once every new one is complete: never half a file, nor a new JSON beside old CSVs. A
    block that fails removes every temporary file (the older set stays as it was); an OSError
    becomes one ``OutputError``: ``option shown: reason; the partial files removed``."""
    temps: list[Path] = []
    try:
        for path in paths:
            temps.append(_new_temp(path))
        yield temps
        for temp, path in zip(temps, paths, strict=True):
            os.replace(temp, path)
    except BaseException as exc:  # a full disk, or a signal: no temporary file left behind
        for temp in temps:
            temp.unlink(missing_ok=True)  # those already renamed are gone
        if isinstance(exc, OSError):
            reason = exc.strerror or str(exc)
            raise OutputError(f"{option} {shown}: {reason}; the partial files removed") from None
        raise


def _new_temp(path: Path) -> Path:
    """An empty file of its own beside ``path`` (``.STEM.PID.part.SUFFIX``: writers that go by
    the suffix, matplotlib's, still see it; the umask's mode, as the file it stands for would
    get)."""
    temp = path.with_name(f".{path.stem}.{os.getpid()}.part{path.suffix}")
    os.close(os.open(temp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o666))
    return temp


def check_distinct(
    outputs: list[tuple[str, Path | None]], inputs: list[tuple[str, Path | None]] | None = None
) -> None:
    """Refuse two outputs on one file, or an output on an input (``analyze drive.log --report
    drive.log`` replaced the recording with its report): one line naming both, before any work.
    The same file is the same inode when both exist, else the same absolute path."""
    seen = [(option, path, True) for option, path in inputs or [] if path is not None]
    for option, path in outputs:
        if path is None or str(path) == os.devnull:
            continue
        for other_option, other, is_input in seen:
            if _same_file(path, other):
                what = "the input: it would be overwritten" if is_input else "also an output"
                raise ConfigurationError(f"{option} {path}: that is {other_option} {other}, {what}")
        seen.append((option, path, False))


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet)
        return a.resolve() == b.resolve()
