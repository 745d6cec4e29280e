"""Bus options the python-can way: ``-i/--interface``, ``-c/--channel``, ``-b/--bitrate``.

Anything not given on the command line comes from python-can's own configuration (``~/.canrc``,
``can.ini``, ``CAN_INTERFACE``/``CAN_CHANNEL`` environment variables), exactly as ``can.Bus()``
reads it.
"""

from __future__ import annotations

import argparse
from typing import Any

import can

from odocan.sim.exceptions import BusSetupError
from odocan.sim.faults import FaultInjectingBus, FaultSpec


def add_bus_arguments(parser: argparse.ArgumentParser, *, required: bool = False) -> None:
    """Add python-can's bus options to ``parser``."""
    group = parser.add_argument_group("bus (python-can; unset values come from its config file)")
    group.add_argument(
        "-i",
        "--interface",
        required=required,
        help="python-can interface: virtual, udp_multicast, socketcan, ...",
    )
    group.add_argument(
        "-c", "--channel", help="channel: e.g. vcan0 (socketcan), 239.74.163.2 (udp_multicast)"
    )
    group.add_argument("-b", "--bitrate", type=int, help="bitrate in bit/s")
    group.add_argument(
        "--bus-arg",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="extra keyword for can.Bus (repeatable), e.g. receive_own_messages=1",
    )


def add_fault_argument(parser: argparse.ArgumentParser) -> None:
    """``--faults SPEC``: inject faults on what this node sends (``sim.faults``)."""
    parser.add_argument(
        "--faults",
        default="",
        metavar="SPEC",
        help="faults on this node's sends: drop=P,burst=P:LEN,dup=P,delay=P:MS,flip=P,"
        "babble=RATE,busoff=T:DUR,seed=N (see README, 'Faults on the bus')",
    )


def parse_faults(args: argparse.Namespace) -> FaultSpec | None:
    """The ``--faults`` option as a spec (None when absent or empty); one-line errors."""
    text = getattr(args, "faults", "") or ""
    return FaultSpec.parse(text) if text else None


def open_bus(args: argparse.Namespace, *, with_faults: bool = True, **overrides: Any) -> can.BusABC:
    """Open the bus the options describe, wrapped in a fault injector when ``--faults`` asks
    (and ``with_faults``); one-line ``BusSetupError`` when it cannot be opened."""
    spec = parse_faults(args) if with_faults else None
    bus = _open_raw_bus(args, **overrides)
    return FaultInjectingBus(bus, spec) if spec is not None and spec.active else bus


def _open_raw_bus(args: argparse.Namespace, **overrides: Any) -> can.BusABC:
    kwargs: dict[str, Any] = {}
    for key in ("interface", "channel", "bitrate"):
        value = getattr(args, key, None)
        if value is not None:
            kwargs[key] = value
    for item in getattr(args, "bus_arg", []):
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise BusSetupError(f"--bus-arg expects KEY=VALUE, got {item!r}")
        kwargs[key] = _auto_type(value)
    kwargs.update(overrides)
    try:
        return can.Bus(**kwargs)
    except (can.CanError, ValueError, OSError, ImportError, TypeError) as exc:
        described = ", ".join(f"{k}={v}" for k, v in kwargs.items()) or "python-can defaults"
        raise BusSetupError(f"cannot open CAN bus ({described}): {exc}") from exc


def _auto_type(text: str) -> Any:
    lowered = text.lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    try:
        return int(text, 0)
    except ValueError:
        try:
            return float(text)
        except ValueError:
            return text
