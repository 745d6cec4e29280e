"""MQTT client ids of at most 23 bytes: what MQTT 3.1.1 guarantees every broker accepts (#13).

MQTT 3.1.1 (3.1.3.1) obliges a server to accept client ids of 1-23 UTF-8 bytes; beyond, it MAY
refuse (CONNACK "identifier rejected"). mosquitto and amqtt accept longer ones, a strict broker
would not. The bridge's ids are ``<client prefix>-<robot>`` (one connection per robot, a
persistent session each) and, for the command reader of a bridge process (one connection for
all its robots, ``host.mqtt.cmdreader``), ``<client prefix>-cmd-<its robots>``. ``client_id``
keeps such a name as it is when it fits (``odocan-bridge-robot001``: a session the broker holds
under it is found again), and otherwise gives a stable short form: the name's first bytes, a
dash and ``HASH_CHARS`` base-36 digits of its SHA-256. Stable (a restarted bridge finds its
sessions again, for the same robots and prefix); distinct for distinct names, up to a hash
collision (~57 bits): each robot's, each shard's, each worker process's reader differ, since
their names (the robots they serve) differ.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from typing import Final

MAX_CLIENT_ID_BYTES: Final = 23  # MQTT 3.1.1, 3.1.3.1: what every server must accept
HASH_CHARS: Final = 11  # base-36 digits of the name's SHA-256 in a shortened id (~57 bits)
_DIGITS: Final = "0123456789abcdefghijklmnopqrstuvwxyz"


def client_id(name: str) -> str:
    """``name`` when it is at most ``MAX_CLIENT_ID_BYTES`` UTF-8 bytes, else its stable short
    form (see the module docstring), at most ``MAX_CLIENT_ID_BYTES`` bytes."""
    raw = name.encode()
    if len(raw) <= MAX_CLIENT_ID_BYTES:
        return name
    head = raw[:MAX_CLIENT_ID_BYTES - HASH_CHARS - 1].decode(errors="ignore")  # whole chars
    return f"{head}-{_base36(hashlib.sha256(raw).digest(), HASH_CHARS)}"


def link_client_id(prefix: str, robot: str) -> str:
    """The client id of ``robot``'s link (``host.mqtt.link.RobotLink``)."""
    return client_id(f"{prefix}-{robot}")


def reader_client_id(prefix: str, robots: Sequence[str]) -> str:
    """The client id of the command reader of a bridge process serving ``robots``."""
    return client_id(f"{prefix}-cmd-{','.join(robots)}")


def _base36(digest: bytes, chars: int) -> str:
    value = int.from_bytes(digest, "big")
    out = []
    for _ in range(chars):
        value, digit = divmod(value, 36)
        out.append(_DIGITS[digit])
    return "".join(out)
