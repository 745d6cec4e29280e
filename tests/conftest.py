"""Every test leaves the logging configuration as it found it.

``odocan bridge``/``fleet``/``monitor`` run in-process here call ``configure_logging``, which sets
the levels and handlers of odocan's and the libraries' loggers for the life of a CLI process; in a
test session that would leak into later tests' stderr.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator

import pytest

from odocan.host.mqtt.options import LIBRARY_LOGGERS, MQTT_LOGGERS


@pytest.fixture(autouse=True)
def _logging_as_found() -> Iterator[None]:
    loggers = [logging.getLogger(name) for name in ("odocan", *MQTT_LOGGERS, *LIBRARY_LOGGERS)]
    saved = [(lg, lg.level, list(lg.handlers), lg.propagate) for lg in loggers]
    yield
    for lg, level, handlers, propagate in saved:
        lg.setLevel(level)
        lg.handlers[:] = handlers
        lg.propagate = propagate
