"""Every test leaves the logging configuration as it found it, and the session caches the DBC
plan in a temporary ``ODOCAN_CACHE_DIR`` (never the user's ``~/.cache/odocan``).

``odocan bridge``/``fleet``/``monitor`` run in-process here call ``configure_logging``, which sets
the levels and handlers of odocan's and the libraries' loggers for the life of a CLI process; in a
test session that would leak into later tests' stderr.

The session runs with Ctrl-C as a terminal gives it: a shell that starts pytest as a background
job without job control (``cmd &`` in a script, ``nohup``) starts it with SIGINT ignored, which
every process it starts inherits across ``exec``; the interpreter then installs no SIGINT handler,
and a SIGINT before odocan installs its own was ignored: ``test_early_sigint``'s 0-50 ms cases
ran their hour-long drive to the end, exit 0 (a full run launched that way, five false failures).

Under ``CI`` (set by the CI runner) hypothesis draws are derandomized: a CI verdict must not
depend on the luck of a draw; local runs keep exploring (what they find becomes an ``@example``).
In both, hypothesis keeps no wall-clock bound of its own (no per-example ``deadline``, no
``too_slow`` health check): an example of 1 ms that a loaded machine (xdist's workers, other
jobs) deschedules for 200 ms fails with ``DeadlineExceeded`` or ``Flaky`` ("unreliable test
timings"), a verdict on the machine's load, not on the code. Under ``CI`` that was so only by
inheritance (hypothesis's own ``ci`` profile, loaded when ``CI`` is set, was the parent of
ours); local runs (31 ``@given`` tests) kept the 200 ms default.
"""

from __future__ import annotations

import logging
import os
import signal
from collections.abc import Iterator

import pytest
from hypothesis import HealthCheck, settings

from odocan.host.mqtt.options import LIBRARY_LOGGERS, MQTT_LOGGERS
from odocan.host.protocol.dbcplan import CACHE_ENV
from tests import sweeps

settings.register_profile("local", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("ci", settings.get_profile("local"), derandomize=True)
settings.load_profile("ci" if os.environ.get("CI") else "local")


def pytest_report_header(config: pytest.Config) -> str:
    return sweeps.header()


@pytest.fixture(autouse=True, scope="session")
def _ctrl_c_as_a_terminal_gives_it() -> Iterator[None]:
    """SIGINT handled (so reset to its default in the processes the tests start), as when a
    terminal starts pytest; restored at the end."""
    inherited = signal.getsignal(signal.SIGINT)
    if inherited == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, inherited)


@pytest.fixture(autouse=True, scope="session")
def _session_cache_dir(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """The whole session (and the processes it starts, which inherit the environment) caches
    DBC plans in a temporary directory; a test that sets its own (``monkeypatch.setenv``) wins
    for its duration."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv(CACHE_ENV, str(tmp_path_factory.mktemp("odocan-cache")))
        yield


@pytest.fixture(autouse=True, scope="session")
def _bytecode_kept(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """Under ``PYTHONDONTWRITEBYTECODE`` (set on CI's machines), every ``python -m odocan`` the
    tests start compiled odocan's ~400 modules afresh (0.5-0.9 s a process, 2-4 % of a run):
    the session's processes keep their bytecode in a cache of the session's own
    (``PYTHONPYCACHEPREFIX``), never in the tree, which the setting is there to spare."""
    if not os.environ.get("PYTHONDONTWRITEBYTECODE"):
        yield
        return
    with pytest.MonkeyPatch.context() as patch:
        patch.delenv("PYTHONDONTWRITEBYTECODE")
        patch.setenv("PYTHONPYCACHEPREFIX", str(tmp_path_factory.getbasetemp().parent / "pyc"))
        yield


@pytest.fixture(autouse=True)
def _logging_as_found() -> Iterator[None]:
    loggers = [logging.getLogger(name) for name in ("odocan", *MQTT_LOGGERS, *LIBRARY_LOGGERS)]
    saved = [(lg, lg.level, list(lg.handlers), lg.propagate) for lg in loggers]
    yield
    for lg, level, handlers, propagate in saved:
        lg.setLevel(level)
        lg.handlers[:] = handlers
        lg.propagate = propagate
