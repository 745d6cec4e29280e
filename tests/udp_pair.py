"""One udp_multicast set-up for the tests that need a real socket: a fresh group and port (runs
in parallel never hear each other: the port from 43000 + a random offset), and a pair of buses
on it, the test skipped where the sandbox has no multicast route."""

from __future__ import annotations

import secrets
from typing import Any

import can
import pytest


def fresh_group() -> tuple[str, int]:
    """A random administratively scoped group and a port of 43000 .. 43899."""
    group = f"239.255.{secrets.randbelow(250) + 1}.{secrets.randbelow(250) + 1}"
    return group, 43000 + secrets.randbelow(900)


def open_pair() -> tuple[can.BusABC, can.BusABC]:
    """Two udp_multicast buses (receiver, sender) on a fresh group, hop limit 0; skips the
    test when the interface cannot open (no multicast route)."""
    group, port = fresh_group()
    kwargs: dict[str, Any] = {"interface": "udp_multicast", "channel": group, "hop_limit": 0,
                              "port": port}
    try:
        rx = can.Bus(**kwargs)
    except Exception as exc:  # no multicast route in this sandbox
        pytest.skip(f"udp_multicast unavailable: {exc}")
    try:
        return rx, can.Bus(**kwargs)
    except Exception as exc:
        rx.shutdown()
        pytest.skip(f"udp_multicast unavailable: {exc}")
