"""``python -m odocan`` in a child process under a resource limit.

A full disk is made without root by RLIMIT_FSIZE with SIGXFSZ ignored: a write past the limit
fails with EFBIG, as a write to a full disk fails with ENOSPC. RLIMIT_AS bounds the address
space, so a regression that reads a device whole fails with MemoryError instead of taking the
machine.

Such a child writes no bytecode. Past RLIMIT_FSIZE the interpreter's own ``.pyc`` write is cut
short without an error and the cut file replaces the whole one: a limited child sharing the
session's bytecode cache (``conftest._bytecode_kept``) left a cut ``.pyc`` there, and every
later ``python -m odocan`` importing that module failed with ``EOFError: marshal data too
short`` (CI, stop 61)."""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
from typing import Any


def limit_file_bytes(limit_bytes: int) -> None:
    """In this process: a write past ``limit_bytes`` fails with EFBIG instead of a SIGXFSZ."""
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))


def run_limited(
    argv: list[str], *, file_bytes: int | None = None, address_bytes: int | None = None,
    **kwargs: Any,
) -> subprocess.CompletedProcess[str]:
    """``python -m odocan ARGV``, its files unable to grow past ``file_bytes`` and its address
    space at most ``address_bytes`` (each when given); output captured as text, not checked."""

    def limit() -> None:
        if file_bytes is not None:
            limit_file_bytes(file_bytes)
        if address_bytes is not None:
            resource.setrlimit(resource.RLIMIT_AS, (address_bytes, address_bytes))

    env = {**kwargs.pop("env", os.environ), "PYTHONDONTWRITEBYTECODE": "1"}
    kwargs.setdefault("timeout", 300)
    return subprocess.run([sys.executable, "-m", "odocan", *argv], env=env, preexec_fn=limit,
                          capture_output=True, text=True, check=False, **kwargs)
