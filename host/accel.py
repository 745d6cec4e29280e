"""The bridge's per-frame path compiled with mypyc, opt-in (issue #13: a fleet worker's CPU).

``ODOCAN_ACCEL=1`` in the environment (``0``: off; anything else exits 2), or ``odocan fleet
--accel`` (``for_children``: its workers): ``odocan.host`` (imported before any of its modules,
in every process, spawned fleet workers included) calls ``install``, which loads the modules
named in ``MODULES`` from a mypyc build in a cache directory instead of their ``.py``. The build is
keyed by a hash of every ``.py`` of the package (a compiled module inlines other modules'
constants and class layouts, so any edit anywhere makes a new build), the interpreter and mypy
versions: it is used only when it matches the sources exactly, never stale. A missing build is
made once (minutes: mypyc + gcc, in a subprocess, under a lock); one that cannot be made leaves
pure Python with a one-line note on stderr. Without the variable nothing here runs: the tests
(which monkeypatch modules a compiled caller would have bound early) run pure Python.

The build goes to ``$ODOCAN_ACCEL_CACHE`` (else ``$XDG_CACHE_HOME/odocan/accel``, else
``~/.cache/odocan/accel``), never next to the sources: an extension module there would shadow
its ``.py`` on import, so a stale one would hide edits. ``python -m odocan.host.accel`` builds
it and prints its directory.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.abc
import importlib.machinery
import importlib.util
import os
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from types import ModuleType

ENV = "ODOCAN_ACCEL"
CACHE_ENV = "ODOCAN_ACCEL_CACHE"
PACKAGE = Path(__file__).parent.parent  # odocan/ (not resolved: its rooms are links in a checkout)
GROUP = "odocan_accel"  # mypyc's shared library: the top-level module ``odocan_accel__mypyc``
MANIFEST = "manifest.txt"  # written last: a build directory without it is not a build

# The per-frame path (cProfile of bench/bridge_frames.py), and the bases of its classes (a
# compiled class's base is compiled too). Not here: host.judge.reference (numpy's types: mypyc
# refuses wrap_delta's constrained TypeVar; its per-frame step, host.judge.refodometry, is here),
# code generated at run time (livedecode, liveplan: exec'd, interpreted whichever way its module
# is loaded).
_JUDGE = PACKAGE / "host" / "judge"  # every live judge (host.judge.live*)
MODULES = (
    *(f"host.judge.{p.stem}" for p in sorted(_JUDGE.glob("live*.py"))),
    *(f"host.judge.{name}" for name in ("tracking", "sources", "posewrongs", "bootticks",
                                        "gapseen", "distance", "reprimereplay", "statuslatch",
                                        "refodometry")),
    *(f"host.mqtt.{name}" for name in ("telemetry", "liveplan", "livedecode", "topics",
                                       "errorbatch", "liveroutes", "livecommands", "lsbround",
                                       "framehold")),
    *(f"host.protocol.{name}" for name in ("e2e_live", "e2e_evidence", "e2e", "e2e_crc", "pose")),
    # Not the fleet's step (sim.*): compiled (node, tickloop, motor_controller, board, cboard,
    # simplan, drivetrain, transport, canbits) it ran more instructions, not fewer: 128.7k ->
    # 148.8k per robot-tick, C firmware, callgrind (issue #13). Its objects are mostly pure
    # (python-can's, the drives', ctypes'), which compiled code reaches by generic attribute
    # look-ups where 3.11's interpreter has specialised inline caches.
)


def sources_key(package: Path = PACKAGE) -> str:
    """The build's key: every ``.py`` of ``package`` (path and bytes), ``MODULES``, this
    interpreter (version, extension suffix) and mypy's version."""
    from importlib.metadata import version  # only when asked: it costs start-up time

    digest = hashlib.sha256()
    for part in (sys.version, importlib.machinery.EXTENSION_SUFFIXES[0], version("mypy"),
                 *MODULES):
        digest.update(part.encode() + b"\0")
    for path in py_files(package):
        digest.update(path.relative_to(package).as_posix().encode() + b"\0")
        digest.update(hashlib.sha256(path.read_bytes()).digest())
    return digest.hexdigest()[:24]


def py_files(package: Path) -> list[Path]:
    """The package's modules in a fixed order (its rooms are followed: links in a checkout)."""
    found = []
    for top, dirs, files in os.walk(package, followlinks=True):
        dirs[:] = sorted(d for d in dirs if not d.startswith((".", "__pycache__")))
        found += [Path(top) / f for f in sorted(files) if f.endswith(".py")]
    return found


def cache_root() -> Path:
    """Where builds live (the module docstring)."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "odocan" / "accel"


def built(build: Path) -> dict[str, Path]:
    """A finished build's extension modules by full name ({} if unfinished or absent)."""
    try:
        lines = (build / MANIFEST).read_text(encoding="utf-8").splitlines()
    except OSError:
        return {}
    return {name: build / rel for name, rel in (line.split("\t") for line in lines if line)}


class _Finder(importlib.abc.MetaPathFinder):
    """Finds the compiled modules (and mypyc's shared library) in one build, before the path."""

    def __init__(self, modules: dict[str, Path]) -> None:
        self.modules = modules

    def find_spec(self, fullname: str, path: Sequence[str] | None = None,
                  target: ModuleType | None = None) -> importlib.machinery.ModuleSpec | None:
        so = self.modules.get(fullname)
        if so is None:
            return None
        loader = importlib.machinery.ExtensionFileLoader(fullname, str(so))
        return importlib.util.spec_from_file_location(fullname, so, loader=loader)


def active() -> dict[str, Path]:
    """The compiled modules this process loads ({}: pure Python)."""
    return next((f.modules for f in sys.meta_path if isinstance(f, _Finder)), {})


def install(*, build: bool = True) -> bool:
    """Load ``MODULES`` compiled from now on, building them first if ``build`` and needed;
    False (and a note on stderr) when pure Python stays."""
    if active():
        return True
    early = sorted(f"odocan.{m}" for m in MODULES if f"odocan.{m}" in sys.modules)
    if early:  # a compiled module must not meet a pure copy of another one
        return _note(f"{early[0]} was imported before the accelerator was installed")
    modules, why = find_build(build=build)
    if not modules:
        return _note(why)
    sys.meta_path.insert(0, _Finder(modules))
    return True


def find_build(*, build: bool = True) -> tuple[dict[str, Path], str]:
    """This version of the sources' build (made first if ``build`` and needed): its modules,
    or {} and why there is none."""
    try:
        key = sources_key()
    except Exception as exc:  # no mypy (importlib.metadata), an unreadable source
        return {}, f"no build key ({type(exc).__name__}: {exc})"
    target = cache_root() / key
    modules = built(target)
    if not modules and build:
        from odocan.host.accelbuild import build_locked

        failure = build_locked(target, PACKAGE, list(MODULES))
        if failure:
            return {}, failure
        modules = built(target)
    return modules, "" if modules else f"no build at {target} (python -m odocan.host.accel)"


@contextlib.contextmanager
def for_children() -> Iterator[bool]:
    """The compiled path for the processes spawned inside (a fleet's workers: ``odocan fleet
    --accel``), whose modules this process imported pure already: the build made here first
    (once: minutes), then ``ODOCAN_ACCEL=1`` in the environment they inherit, as it was after.
    Yields whether they get it (False: one line on stderr, pure Python)."""
    if active():  # this process runs compiled: ODOCAN_ACCEL=1 is already set
        yield True
        return
    modules, why = find_build()
    if not modules:
        yield _note(why)
        return
    before = os.environ.get(ENV)
    os.environ[ENV] = "1"
    try:
        yield True
    finally:
        if before is None:
            del os.environ[ENV]
        else:
            os.environ[ENV] = before


def _note(why: str) -> bool:
    print(f"odocan: compiled per-frame path off, pure Python ({why})", file=sys.stderr)
    return False


def main() -> int:
    """Build (if needed) and print the build's directory."""
    if not install():
        return 1
    print(cache_root() / sources_key())
    return 0


if __name__ == "__main__":
    sys.exit(main())
