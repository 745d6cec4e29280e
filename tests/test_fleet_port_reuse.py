"""``fleet --port P`` right after a run on P (trial13).

From outside: ``odocan fleet -n 3 --port 43222 --duration 8`` twice in a row; the second ended at
once with ``error: --port 43222: 127.0.0.1:43222 cannot be used (Address already in use)``
although nothing listened there: the first run's connections were in TIME_WAIT (``ss -tan``),
which block a bind without SO_REUSEADDR, while the broker's own listener (asyncio's
``start_server``) sets it and could have bound. A port something listens on is still refused.
"""

from __future__ import annotations

import socket

import pytest

from odocan.host.mqtt.shards import check_port_free
from odocan.sim.exceptions import ConfigurationError


def _time_wait_port() -> int:
    """A loopback port left with a server-side connection in TIME_WAIT and no listener, as the
    embedded broker leaves it (its listener is asyncio's: SO_REUSEADDR)."""
    with socket.socket() as listener:
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        listener.bind(("127.0.0.1", 0))
        listener.listen()
        port = int(listener.getsockname()[1])
        client = socket.create_connection(("127.0.0.1", port))
        served, _ = listener.accept()
        served.close()  # the server closes first: TIME_WAIT on its side, on ``port``
        client.recv(1)
        client.close()
    return port


def test_a_port_left_in_time_wait_is_free_for_the_next_run_a_listened_one_is_not() -> None:
    port = _time_wait_port()
    check_port_free(port)
    with socket.socket() as listener:
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as asyncio's server
        listener.bind(("127.0.0.1", port))
        listener.listen()
        with pytest.raises(ConfigurationError, match="cannot be used"):
            check_port_free(port)
