"""The topic map, the QoS classes and the JSON payloads of the MQTT side.

Every topic is ``odocan/<robot>/<leaf>``:

=================  ===============  ====  ======  =========================================
leaf               direction        QoS   retain  payload (JSON; units in the key names)
=================  ===============  ====  ======  =========================================
pose               bridge -> you    0     no      on-board pose (ODOM_POSE_X/Y, ODOM_TWIST)
reference          bridge -> you    0     no      float64 reference at the same encoder frame
truth              bridge -> you    0     no      SIM_TRUTH (simulated robots only)
error              bridge -> you    0     no      pose - reference, pose - truth
rates              bridge -> you    0     no      frames/s per message, E2E counts
status             bridge -> you    1     yes     online/offline (last will), firmware state
cmd/nav_goal       you -> bridge    1     no      a navigation goal (NAV_GOAL frames)
cmd/set_pose       you -> bridge    1     no      set the on-board pose (ODOM_SET_POSE)
cmd/config         you -> bridge    1     no      robot parameters (ODOM_CONFIG)
cmd/result         bridge -> you    1     no      accepted / rejected (reason) / acked / nacked
=================  ===============  ====  ======  =========================================

Headings are named for what they are: ``heading_rad`` wrapped to (-pi, pi],
``heading_unwrapped_rad`` cumulative (``host.protocol.pose.heading_fields``); enums go out by
their DBC names.

Telemetry is QoS 0 (the next sample replaces a lost one); status, commands and their results are
QoS 1 (at least once, buffered by the bridge while the broker is away).
"""

from __future__ import annotations

import json
import re
import time
from typing import Any, Final

from odocan.host.jsonutil import finite

PREFIX: Final = "odocan"
TELEMETRY_LEAVES: Final = ("pose", "reference", "truth", "error", "rates")
STATUS_LEAF: Final = "status"
COMMANDS: Final = ("nav_goal", "set_pose", "config")
RESULT_LEAF: Final = "cmd/result"
QOS_TELEMETRY: Final = 0
QOS_RELIABLE: Final = 1  # status, commands, results
ROBOT_NAME: Final = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")


def topic(robot: str, leaf: str) -> str:
    """``odocan/<robot>/<leaf>``."""
    return f"{PREFIX}/{robot}/{leaf}"


def command_filter(robot: str) -> str:
    """The subscription of one robot's commands: ``odocan/<robot>/cmd/+``."""
    return f"{PREFIX}/{robot}/cmd/+"


def command_of(topic_name: str) -> tuple[str, str] | None:
    """``odocan/<robot>/cmd/<name>`` (what ``command_filter`` matches) -> (robot, name); None
    for any other topic. A ``cmd/+`` subscription is no promise of it: amqtt (the embedded
    broker) sends a client, as it connects, the retained messages of the filters ANY client
    holds (its ``Broker`` walks every subscription, not the session's): a monitor's
    ``odocan/+/#`` brought every robot's ``status`` to each link, taken for a command."""
    parts = topic_name.split("/")
    if len(parts) != 4 or parts[0] != PREFIX or parts[2] != "cmd":
        return None
    return parts[1], parts[3]


def qos(leaf: str) -> int:
    """The QoS class of a leaf: 0 for telemetry, 1 for status, commands and results."""
    return QOS_TELEMETRY if leaf in TELEMETRY_LEAVES else QOS_RELIABLE


def retained(leaf: str) -> bool:
    """Only ``status`` is retained (a new subscriber learns at once who is online)."""
    return leaf == STATUS_LEAF


def split(topic_name: str) -> tuple[str, str] | None:
    """``odocan/<robot>/<leaf>`` -> (robot, leaf); None for any other topic."""
    parts = topic_name.split("/", 2)
    if len(parts) != 3 or parts[0] != PREFIX or not ROBOT_NAME.match(parts[1]):
        return None
    return parts[1], parts[2]


def check_robot_name(name: str) -> str:
    """``name`` when it is usable as one topic level (letters, digits, ``_.-``), else ValueError."""
    if not ROBOT_NAME.match(name):
        raise ValueError(f"robot name {name!r}: use 1-64 of A-Z a-z 0-9 _ . -")
    return name


# json.dumps with these options would build its encoder per call: built once (the same text);
# no circular check (the payloads are trees built here: no id() noted per dict and list)
_COMPACT: Final = json.JSONEncoder(separators=(",", ":"), allow_nan=False, check_circular=False)
# ... and its ``encode`` would still make its C encoder (and a float formatter) per call: the C
# encoder ``JSONEncoder.iterencode`` makes for these options, made once (None without _json)
_MAKE_C_ENCODER: Final = getattr(json.encoder, "c_make_encoder", None)  # (not in the stubs)
_C_ENCODE: Final = None if _MAKE_C_ENCODER is None else _MAKE_C_ENCODER(
    None, _COMPACT.default, json.encoder.encode_basestring_ascii, None, ":", ",", False, False,
    False)  # markers, default, strings, indent, separators, sort_keys, skipkeys, allow_nan


def dumps(payload: object) -> bytes:
    """Compact JSON of any JSON value (a publication is a dict; a list is taken too: mypyc's
    compiled ``dumps`` checks what its annotation says); non-finite floats become null (JSON
    has no NaN). Encoded as it is first
    (every publication of every robot comes here); only a payload with a NaN or an infinity
    (``ValueError``) is copied with them as null (``finite``) and encoded again."""
    try:
        if _C_ENCODE is not None:
            return "".join(_C_ENCODE(payload, 0)).encode()
        return _COMPACT.encode(payload).encode()
    except ValueError:
        return json.dumps(finite(payload), separators=(",", ":")).encode()


def stamp(payload: dict[str, Any]) -> dict[str, Any]:
    """``payload`` with ``unix_s`` (wall clock when published, s since the epoch)."""
    payload["unix_s"] = round(time.time(), 6)
    return payload


def status_payload(robot: str, state: str, **extra: Any) -> dict[str, Any]:
    """A ``status`` payload: ``{"robot", "state": "online"|"offline", ...}``."""
    return stamp({"robot": robot, "state": state, **extra})
