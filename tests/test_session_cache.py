"""The test session never writes the DBC plan cache into the user's ``~/.cache/odocan``:
tests/conftest.py points ``ODOCAN_CACHE_DIR`` at the session's temporary directory, whatever the
environment that started pytest said."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from odocan.host.protocol.dbcplan import cache_dir


def test_the_session_caches_plans_under_its_temporary_directory(
    tmp_path_factory: pytest.TempPathFactory,
) -> None:
    base = tmp_path_factory.getbasetemp()
    assert cache_dir().is_relative_to(base), cache_dir()
    assert not cache_dir().is_relative_to(Path.home() / ".cache")


def test_a_child_process_inherits_the_sessions_cache(
    tmp_path_factory: pytest.TempPathFactory,
) -> None:
    probe = "from odocan.host.protocol.dbcplan import cache_dir; print(cache_dir())"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         check=True, timeout=120).stdout.strip()
    assert Path(out) == cache_dir()
    assert Path(out).is_relative_to(tmp_path_factory.getbasetemp())

