"""MQTT client ids of 1-23 characters of 0-9a-zA-Z: what MQTT 3.1.1 makes every broker accept.

Issue #13. MQTT 3.1.1 (3.1.3.1) obliges a server to accept client ids of 1-23 UTF-8 bytes that
contain only 0-9a-zA-Z; beyond either, it MAY refuse (CONNACK "identifier rejected").
mosquitto and amqtt accept longer ids and other characters, a strict broker would not.

The bridge's ids name ``<client prefix>-<robot>`` (one connection per robot, a persistent
session each) and, for the command reader of a bridge process (one connection for all its
robots, ``host.mqtt.cmdreader``), ``<client prefix>/cmd/<its robots>``. ``client_id`` turns
such a name into an id:

* a link whose prefix and robot are both 0-9a-zA-Z and fit together: the two joined
  (``odocanbridge`` + ``robot001`` = ``odocanbridgerobot001``, the default prefix's), readable
  in the broker's log; distinct robots under one prefix give distinct ids;
* anything else (a name too long, a prefix or robot name with other characters, every
  reader): a stable short form, the name's first ``HEAD_CHARS`` letters and digits then
  ``HASH_CHARS`` base-36 digits of the whole name's SHA-256 (``bench-flat-1764...`` gives
  ``benchflat176`` + 11 digits).

A ``--client-prefix`` with other characters (``my-bridge``) is therefore mapped, not refused:
its ids conform, in the short form (refusing it would break every deployment that set one).
Stable (a restarted bridge finds its sessions again, for the same robots and prefix);
distinct for distinct names, up to a hash collision (~57 bits): each robot's, each shard's,
each worker process's reader differ, since their names (the robots they serve) differ.
The ids up to the fifteenth pass were ``odocan-bridge-<robot>``: a broker keeps such a
persistent session (and the QoS 1 commands queued in it) under the old id until its own
expiry; the new id starts a clean session once.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from typing import Final

MAX_CLIENT_ID_BYTES: Final = 23  # MQTT 3.1.1, 3.1.3.1: what every server must accept
HASH_CHARS: Final = 11  # base-36 digits of the name's SHA-256 in a shortened id (~57 bits)
HEAD_CHARS: Final = MAX_CLIENT_ID_BYTES - HASH_CHARS  # the name's letters and digits before it
ID_CHARS: Final = frozenset("0123456789abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ")
DEFAULT_PREFIX: Final = "odocanbridge"  # ``--client-prefix``'s default: 0-9a-zA-Z only
_DIGITS: Final = "0123456789abcdefghijklmnopqrstuvwxyz"


def conforms(client_id: str) -> bool:
    """True when ``client_id`` is 1-23 characters of 0-9a-zA-Z (MQTT 3.1.1's guarantee)."""
    return 1 <= len(client_id) <= MAX_CLIENT_ID_BYTES and ID_CHARS.issuperset(client_id)


def short_id(name: str) -> str:
    """The stable short form of ``name``: its first ``HEAD_CHARS`` letters and digits (ASCII),
    then ``HASH_CHARS`` base-36 digits of its UTF-8 bytes' SHA-256; conforming."""
    head = "".join(c for c in name if c in ID_CHARS)[:HEAD_CHARS]
    return head + _base36(hashlib.sha256(name.encode()).digest(), HASH_CHARS)


def link_client_id(prefix: str, robot: str) -> str:
    """The client id of ``robot``'s link (``host.mqtt.link.RobotLink``): ``prefix`` and
    ``robot`` joined when both conform and fit, else the short form of ``<prefix>-<robot>``."""
    joined = prefix + robot
    if prefix and robot and conforms(joined):
        return joined
    return short_id(f"{prefix}-{robot}")


def reader_client_id(prefix: str, robots: Sequence[str]) -> str:
    """The client id of the command reader of a bridge process serving ``robots``: always the
    short form of ``<prefix>/cmd/<robots, comma-separated>`` (never a link's joined form; a
    robot name holds no ``/``, so no link's name ``<prefix>-<robot>`` is a reader's)."""
    return short_id(f"{prefix}/cmd/{','.join(robots)}")


def _base36(digest: bytes, chars: int) -> str:
    value = int.from_bytes(digest, "big")
    out = []
    for _ in range(chars):
        value, digit = divmod(value, 36)
        out.append(_DIGITS[digit])
    return "".join(out)
