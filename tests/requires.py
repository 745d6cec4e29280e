"""System packages the tests need: skip with the reason on a developer's machine, fail in CI.

``.ci/run`` installs mosquitto, can-utils and the ARM cross toolchain; under ``CI=true`` a missing
one means the install step broke, and a skip there would keep CI green while testing less.
"""

from __future__ import annotations

import os
import shutil

import pytest

IN_CI = os.environ.get("CI") == "true"


def require_executables(*names: str, install: str) -> None:
    """Skip (fail under CI=true) unless every executable in ``names`` is on PATH."""
    missing = [name for name in names if shutil.which(name) is None]
    if not missing:
        return
    reason = f"{', '.join(missing)} not installed ({install})"
    if IN_CI:
        pytest.fail(f"{reason}: .ci/run installs it, so in CI its absence is a failure")
    pytest.skip(reason)
