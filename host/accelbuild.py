"""The mypyc build behind ``host.accel``: once per key, under a lock, in a subprocess.

The subprocess (this module as ``__main__``) runs mypyc on the module files and gcc through
setuptools' ``build_ext``, with its working directory in the build's own temporary directory:
no ``pyproject.toml`` is read there (setuptools would validate the project's, mypy would take
its file list) and nothing is written near the sources. A finished build is renamed into place
with its manifest, so a reader sees a whole build or none; a failed one leaves ``KEY.failed``
(its reason and log), so the next process (a fleet's other workers) does not spend minutes
failing again: delete it to retry.
"""

from __future__ import annotations

import fcntl
import importlib.machinery
import importlib.util
import os
import shutil
import subprocess
import sys
from pathlib import Path

SUFFIX = importlib.machinery.EXTENSION_SUFFIXES[0]


def build_locked(target: Path, package: Path, modules: list[str]) -> str | None:
    """Build ``modules`` of ``package`` into ``target`` (named by the sources' key) unless a
    build is there; None, or why not."""
    target.parent.mkdir(parents=True, exist_ok=True)
    failed = target.with_name(target.name + ".failed")
    with open(target.with_name(target.name + ".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # one builder; the others wait, then find its build
        if (target / "manifest.txt").exists():
            return None
        if failed.exists():
            return failed.read_text(encoding="utf-8").strip()
        why = _missing_tools() or _build(target, package, modules)
        if why is not None:
            failed.write_text(why + "\n", encoding="utf-8")
        return why


def _missing_tools() -> str | None:
    if importlib.util.find_spec("mypyc") is None:
        return "mypyc is not installed (pip install mypy)"
    if not shutil.which(os.environ.get("CC", "gcc").split()[0]):
        return "no C compiler (gcc, or $CC)"
    return None


def _build(target: Path, package: Path, modules: list[str]) -> str | None:
    """Compile a snapshot of the sources in a fresh temporary directory, then rename it to
    ``target``: the snapshot's key must be ``target``'s (an edit while the build runs would
    otherwise compile other sources than the key names)."""
    from odocan.host.accel import py_files, sources_key

    tmp = target.with_name(f"{target.name}.tmp{os.getpid()}")
    shutil.rmtree(tmp, ignore_errors=True)
    snapshot = tmp / "src" / "odocan"
    for path in py_files(package):
        copy = snapshot / path.relative_to(package)
        copy.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(path, copy)
    if sources_key(snapshot) != target.name:
        shutil.rmtree(tmp, ignore_errors=True)
        return "the sources changed as the build started"
    files = [snapshot / (m.replace(".", "/") + ".py") for m in modules]
    log = tmp / "build.log"
    print(f"odocan: compiling the per-frame path with mypyc into {target} (once per version of "
          "the sources: minutes)", file=sys.stderr, flush=True)
    env = {k: v for k, v in os.environ.items() if k != "ODOCAN_ACCEL"}
    here = str(Path(__file__).parent.parent.parent)  # this odocan, whatever the cwd (a relative
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [here, env.get("PYTHONPATH")]))  # path)
    with open(log, "wb") as out:
        done = subprocess.run([sys.executable, "-m", "odocan.host.accelbuild", str(tmp),
                               *map(str, files)], cwd=tmp, env=env, stdout=out,
                              stderr=subprocess.STDOUT, check=False)
    if done.returncode != 0:
        kept = target.with_name(target.name + ".log")
        shutil.copyfile(log, kept)
        shutil.rmtree(tmp, ignore_errors=True)
        return f"the mypyc build failed (exit {done.returncode}): see {kept}"
    lib = tmp / "lib"
    lines = [f"{_module_name(so.relative_to(lib))}\t{so.relative_to(tmp).as_posix()}"
             for so in sorted(lib.rglob("*" + SUFFIX))]
    (tmp / "manifest.txt").write_text("".join(line + "\n" for line in lines), encoding="utf-8")
    tmp.rename(target)
    return None


def _module_name(relative: Path) -> str:
    return relative.as_posix()[: -len(SUFFIX)].replace("/", ".")


def compile_into(out: Path, files: list[str]) -> None:
    """mypyc, then gcc: ``out/lib`` gets the extension modules (and mypyc's shared library)."""
    from mypyc.build import mypycify
    from setuptools import Distribution

    from odocan.host.accel import GROUP

    flags = ["--ignore-missing-imports", f"--cache-dir={out / 'mypy_cache'}"]
    modules = mypycify([*files, *flags], opt_level="3", multi_file=True,
                       target_dir=str(out / "c"), group_name=GROUP)
    dist = Distribution({"name": GROUP, "ext_modules": modules})
    build_ext = dist.get_command_obj("build_ext")
    build_ext.build_lib, build_ext.build_temp = str(out / "lib"), str(out / "tmp")
    build_ext.parallel = os.cpu_count() or 1
    build_ext.ensure_finalized()
    build_ext.run()


if __name__ == "__main__":
    compile_into(Path(sys.argv[1]), sys.argv[2:])
