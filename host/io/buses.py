"""Bus options the python-can way: ``-i/--interface``, ``-c/--channel``, ``-b/--bitrate``.

Anything not given on the command line comes from python-can's own configuration (``~/.canrc``,
``can.ini``, ``CAN_INTERFACE``/``CAN_CHANNEL`` environment variables), exactly as ``can.Bus()``
reads it.

**udp_multicast groups are isolated by port.** python-can's ``udp_multicast`` binds
``0.0.0.0:43113`` whatever the group, so a socket joined to one group also receives every other
group's datagrams sent to that port: two rigs on one machine hear each other. Every odocan node
(``open_bus`` here, and the pytest plugin's external backend) therefore opens a udp_multicast
bus on a port derived from its group (``udp_port_for_group``: CRC-32 of the group's text, folded
into 20000..29999, below Linux's ephemeral range) unless ``port`` is given (``--bus-arg
port=43113`` speaks to python-can's default, e.g. a peer that does not derive ports).
"""

from __future__ import annotations

import argparse
import math
import sys
import zlib
from typing import Any

import can

from odocan.sim.exceptions import BusSetupError, ConfigurationError
from odocan.sim.faults import FaultInjectingBus, FaultSpec
from odocan.sim.faultspec import mcu_episodes, mcu_refused

UDP_PORT_BASE, UDP_PORT_SPAN = 20000, 10000  # derived udp_multicast ports: 20000..29999
UDP_DEFAULT_GROUP = "ff15:7079:7468:6f6e:6465:6d6f:6d63:6173"  # python-can's default channel
BABBLE_MAX_PER_S = 20_000.0  # on the wire: 10 000 from each of the rig's two handles, more
# than a 1 Mbit/s bus carries of 8-byte frames
DELAY_MAX_MS = 60_000.0
BUSOFF_MAX_S = 86_400.0
FAULT_SEED_LIMIT = 2**32
# python-can's keywords of every bus (``can.Bus``, ``BusABC``; its configuration's keys)
COMMON_BUS_ARGS = frozenset({"interface", "channel", "bitrate", "data_bitrate", "fd",
                             "can_filters", "receive_own_messages", "timing", "context",
                             "config_context", "ignore_config", "state"})


def add_bus_arguments(parser: argparse.ArgumentParser, *, required: bool = False) -> None:
    """Add python-can's bus options to ``parser``."""
    group = parser.add_argument_group("bus (python-can; unset values come from its config file)")
    group.add_argument(
        "-i",
        "--interface",
        required=required,
        help="python-can interface: virtual, udp_multicast, socketcan, ... "
        "(default: python-can's config)",
    )
    group.add_argument(
        "-c",
        "--channel",
        help="channel: e.g. vcan0 (socketcan), 239.74.163.2 (udp_multicast, on a UDP port "
        "derived from the group unless --bus-arg port=N) (default: python-can's config)",
    )
    group.add_argument(
        "-b", "--bitrate", type=bus_bitrate, metavar="BIT/S",
        help=f"bitrate in bit/s, 1 .. {MAX_BITRATE} (default: python-can's config)",
    )
    group.add_argument(
        "--bus-arg",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="extra keyword for can.Bus (repeatable), e.g. receive_own_messages=1",
    )


MAX_BITRATE = 1_000_000  # ISO 11898-1: CAN's nominal (arbitration) bitrate is at most 1 Mbit/s


def bus_bitrate(text: str) -> int:
    """``-b/--bitrate`` of a live bus: a whole number of bit/s, 1 .. ``MAX_BITRATE`` (an
    interface such as ``virtual`` ignores it: ``-b -5`` was taken without a word)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number of bit/s") from None
    if not 0 < value <= MAX_BITRATE:
        raise argparse.ArgumentTypeError(
            f"{text!r}: a CAN bitrate is 1 .. {MAX_BITRATE} bit/s (ISO 11898-1)")
    return value


def add_fault_argument(parser: argparse.ArgumentParser) -> None:
    """``--faults SPEC``: inject faults on what this node sends (``sim.faults``)."""
    parser.add_argument(
        "--faults",
        action="append",
        default=[],
        metavar="SPEC",
        help="faults on this node's sends: drop=P,burst=P:LEN,dup=P,delay=P:MS,flip=P,"
        "babble=RATE[:ID[:T:DUR]],busoff=T:DUR,seed=N (babble's RATE: frames/s on the wire; "
        "seed: default --seed where the command has one, else 0); odocan run only, the "
        "firmware MCU's own: stall=T:DUR (halted from T s for DUR s), reboot=T[:DUR] (reset "
        "at T s, DUR s of boot), each repeatable; --faults given twice adds the second SPEC "
        "to the first; docs/bus.md, 'Faults on the bus'",
    )


def parse_faults(args: argparse.Namespace, *, mcu: bool = False) -> FaultSpec | None:
    """The ``--faults`` options as one spec (None when absent or empty; given twice, the two
    joined: ``--faults delay=0.1:20 --faults busoff=4:0.3`` is ``delay=0.1:20,busoff=4:0.3``,
    and a key two of them set is refused as within one), within the limits a run
    can honour (``check_fault_limits``); one-line errors. Its seed, unless the text sets one:
    the command's ``--seed`` (0 for a command without one). ``mcu``: the command can halt and
    reset the firmware's MCU (``odocan run``); elsewhere stall and reboot are refused before
    any bus is opened."""
    given = getattr(args, "faults", None) or []
    text = ",".join(part for part in ([given] if isinstance(given, str) else given) if part)
    if not text:
        return None
    spec = FaultSpec.parse(text, seed=getattr(args, "seed", 0))
    check_fault_limits(spec)
    if spec.mcu_active and not mcu:
        raise mcu_refused(spec)
    return spec


def check_fault_limits(spec: FaultSpec) -> None:
    """Upper bounds on top of ``FaultSpec``'s own checks: babble, delay, bus-off, seed."""
    limits = [
        ("babble", spec.babble, BABBLE_MAX_PER_S, "RATE frames/s"),
        ("delay", spec.delay_ms, DELAY_MAX_MS, "MS"),
    ]
    episodes = [("busoff", spec.busoff)] if spec.busoff is not None else []
    for key, episode in [*episodes, *mcu_episodes(spec)]:  # the episodes: a day at most
        limits += [(key, episode.at_s, BUSOFF_MAX_S, "T s"),
                   (key, episode.duration_s, BUSOFF_MAX_S, "DUR s")]
    for key, value, limit, what in limits:
        if not (math.isfinite(value) and value <= limit):
            raise ConfigurationError(
                f"faults: {key}: {what} must be at most {limit:g}, got {value:g}"
            )
    if not 0 <= spec.seed < FAULT_SEED_LIMIT:
        raise ConfigurationError(f"faults: seed={spec.seed}: must be in [0, 2^32)")


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
        kwargs[key] = auto_type(value)
    kwargs.update(overrides)
    kwargs = isolated_bus_kwargs(kwargs)
    for key in unread_bus_args(kwargs.get("interface"), [
            item.partition("=")[0] for item in getattr(args, "bus_arg", [])]):
        print(f"warning: --bus-arg {key}: not a parameter of python-can's "
              f"{kwargs.get('interface')} interface; it may be ignored", file=sys.stderr)
    try:
        return can.Bus(**kwargs)
    except (can.CanError, ValueError, OSError, ImportError, TypeError) as exc:
        _release_half_made(exc)
        described = ", ".join(f"{k}={v}" for k, v in kwargs.items()) or "python-can defaults"
        raise BusSetupError(f"cannot open CAN bus ({described}): {exc}") from exc


def unread_bus_args(interface: Any, keys: list[str]) -> list[str]:
    """The ``--bus-arg`` keys neither the interface class's named ``__init__`` parameters nor
    python-can's common ones (``COMMON_BUS_ARGS``) take: python-can passes any keyword on in
    ``**kwargs`` (``--bus-arg bogus=1`` was accepted silently). A warning, not a refusal: some
    interfaces read options from their ``**kwargs`` (kvaser, pcan), which no signature shows.
    [] when the interface is unknown here (python-can's own error says so)."""
    import inspect

    from can.interface import _get_class_for_interface

    if not isinstance(interface, str) or not keys:
        return []
    try:
        cls = _get_class_for_interface(interface)
        named = set(inspect.signature(cls.__init__).parameters)
    except (ImportError, ValueError, TypeError, can.CanError):
        return []
    return [key for key in keys if key not in named and key not in COMMON_BUS_ARGS]


def _release_half_made(exc: BaseException) -> None:
    """Shut down the bus whose constructor raised ``exc`` (found in its traceback): else its
    ``__del__`` adds "UdpMulticastBus was not properly shut down" after the one error line."""
    tb = exc.__traceback__
    while tb is not None:
        bus = tb.tb_frame.f_locals.get("self")
        if isinstance(bus, can.BusABC):
            try:
                bus.shutdown()
            except Exception:  # half made: what shutdown() releases may not exist yet
                bus._is_shutdown = True  # what BusABC.__del__ checks
        tb = tb.tb_next


def udp_port_for_group(group: str) -> int:
    """The UDP port odocan uses for a udp_multicast ``group`` (module docstring)."""
    return UDP_PORT_BASE + zlib.crc32(group.strip().lower().encode("ascii", "replace")) % (
        UDP_PORT_SPAN
    )


def isolated_bus_kwargs(kwargs: dict[str, Any]) -> dict[str, Any]:
    """``kwargs`` for ``can.Bus`` with ``port`` derived from the group on ``udp_multicast``
    (unless given); other interfaces unchanged. Only keywords given here are seen: a
    udp_multicast bus configured entirely in python-can's config file keeps its own port."""
    if kwargs.get("interface") != "udp_multicast" or "port" in kwargs:
        return kwargs
    group = str(kwargs.get("channel") or UDP_DEFAULT_GROUP)
    return {**kwargs, "port": udp_port_for_group(group)}


def auto_type(text: str) -> Any:
    """A python-can keyword's value as text -> its type: ``true``/``false``, an integer in any
    base Python reads (``0x10`` is 16), a float, or the text itself. One rule for ``--bus-arg``
    and the pytest kit's ``--odocan-bus``."""
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
