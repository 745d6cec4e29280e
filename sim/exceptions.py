"""The one error hierarchy of sim/ and host/ (python-can's ``CanError`` tree is the model).

Every error a person can cause (a bad option, profile, scenario, log line, DBC) is an
``OdocanError``; the CLI turns it into one line ``error: ...`` and exit code 2.
"""

from __future__ import annotations


class OdocanError(Exception):
    """Base of every odocan error."""


class ConfigurationError(OdocanError, ValueError):
    """A bad parameter: robot profile, error model, scenario, fault spec, option value."""


class BusSetupError(OdocanError):
    """A CAN interface could not be opened (unknown interface, missing channel, no vcan)."""


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where Ctrl-C raises ``KeyboardInterrupt`` (and caught wherever that is):
    the CLI ends a command stopped by it before its verdict with exit code 143, not 130."""
