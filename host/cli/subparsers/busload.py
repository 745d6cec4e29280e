"""``odocan busload``: bus utilization and worst-case response times from the DBC.

Every message of the DBC (``--dbc``, default dbc/odocan.dbc) and every
``--add NAME:ID:DLC:CYCLE_MS`` is analysed at ``--bitrate`` by the revised analysis of Davis,
Burns, Bril & Lukkien (2007) (``host.judge.schedulability``): worst-case frame length with bit
stuffing, queuing jitter J from the sender's tick, blocking B by one lower-priority frame, the
worst response R over every instance in the busy period, the deadline D (the cycle time unless
the DBC's ``GenMsgDeadlineTime`` says otherwise) and the slack D - R.

Assumptions, printed under the table and written to the report:

* A sender's tick is the shortest cycle among its messages unless ``--tick-ms NODE=MS`` says
  otherwise (odocan's firmware ticks every 10 ms: ``--tick-ms ODOM_MCU=10``). A cyclic frame is
  queued at the first tick at or after it falls due: J = tick - gcd(cycle, tick), 0 when the cycle
  is a multiple of the tick; ``--queue-jitter-ms`` adds the spread of the moment in a tick at which
  frames are queued (default 0).
* A message without a cycle time is named and treated as sporadic: its minimum inter-arrival time is
  its ``GenMsgDelayTime``, else ``--sporadic-ms``, else the DBC's shortest cycle time; it is queued
  in the tick that produces it.

Exit 0 when every message meets its deadline, 1 when one can miss it, 2 on bad input (a bitrate
that is not a CAN bitrate, a utilization over 100 %, a malformed ``--add``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rich import box
from rich.console import Console
from rich.table import Table

from odocan.host.cli.subparsers.analyze import load_dbc
from odocan.host.jsonutil import write_report
from odocan.host.judge.schedulability import (
    BITRATES,
    MAX_DLC,
    NS_PER_MS,
    BusLoad,
    BusMessage,
    analyse_bus,
    frame_bits,
    messages_from_dbc,
    ms_to_ns,
)
from odocan.sim.contract import database
from odocan.sim.exceptions import ConfigurationError


def add_subparser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``odocan busload``."""
    parser = subparsers.add_parser(
        "busload",
        help="bus utilization and worst-case response time of every DBC message",
        description="Bus utilization and, per message, the worst-case response time by the "
        "revised CAN analysis of Davis et al. (2007), the deadline and the slack. Exit 0 when "
        "every message meets its deadline, 1 when one can miss it, 2 on bad input.",
    )
    parser.add_argument("--dbc", type=Path, metavar="PATH", help="default: dbc/odocan.dbc")
    parser.add_argument(
        "-b",
        "--bitrate",
        type=_bitrate,
        default=500_000,
        help=f"bit/s, one of {', '.join(map(str, BITRATES))} (default: 500000)",
    )
    parser.add_argument(
        "--add",
        action="append",
        default=[],
        metavar="NAME:ID:DLC:CYCLE_MS[:SENDER]",
        help="what if this message were added (ID decimal or 0x hex; above 0x7FF: 29-bit)",
    )
    parser.add_argument(
        "--tick-ms",
        action="append",
        default=[],
        metavar="NODE=MS",
        help="a sender's tick period (default: the shortest period of its messages)",
    )
    parser.add_argument(
        "--queue-jitter-ms",
        default="0",
        metavar="MS",
        help="spread of the queuing moment within a sender's tick (default: 0)",
    )
    parser.add_argument(
        "--sporadic-ms",
        metavar="MS",
        help="min inter-arrival of messages without cycle time or GenMsgDelayTime "
        "(default: the DBC's shortest cycle time)",
    )
    parser.add_argument("--report", type=Path, metavar="PATH", help="write the JSON report here"
                        " (- for stdout: the summary then goes to stderr)")
    parser.set_defaults(func=_do_busload)


def _bitrate(text: str) -> int:
    """``--bitrate``: one of the standard CAN bitrates, in bit/s."""
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value not in BITRATES:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a CAN bitrate (use one of {', '.join(map(str, BITRATES))})"
        )
    return value


def _do_busload(args: argparse.Namespace) -> int:
    if args.report is not None and not args.report.parent.is_dir():
        raise ConfigurationError(f"--report {args.report}: directory {args.report.parent} missing")
    db = load_dbc(args.dbc) if args.dbc is not None else database()
    messages = messages_from_dbc(db, sporadic_ms=args.sporadic_ms)
    nodes = {node.name for node in getattr(db, "nodes", [])}
    nodes |= {sender for message in messages for sender in message.senders}
    messages += [parse_added(text, nodes) for text in args.add]
    _check_unique(messages)
    ticks = parse_ticks(args.tick_ms, messages)
    queue_jitter_ns = ms_to_ns(args.queue_jitter_ms, "--queue-jitter-ms", allow_zero=True)
    load = analyse_bus(messages, args.bitrate, ticks_ns=ticks, queue_jitter_ns=queue_jitter_ns)
    report = load.as_dict()
    report["dbc"] = str(args.dbc) if args.dbc is not None else "dbc/odocan.dbc"
    report["added"] = list(args.add)
    if args.report is not None:
        write_report(args.report, report)
    console = Console(file=sys.stdout, highlight=False, width=120)
    print_busload(load, console, title=f"odocan busload: {report['dbc']}")
    return 0 if load.schedulable else 1


def parse_added(text: str, nodes: set[str] | None = None) -> BusMessage:
    """``NAME:ID:DLC:CYCLE_MS[:SENDER]`` as a cyclic message; malformed text is a one-line error.

    Without SENDER the message has a node of its own, ``(NAME)``, ticking at its cycle (J = 0).
    SENDER must be one of ``nodes`` (the DBC's, when given): a typo would otherwise be a node
    of its own, analysed without a word. An ID above 0x7FF is a 29-bit ID.
    """
    what = f"--add {text!r}"
    fields = [field.strip() for field in text.split(":")]
    if len(fields) not in (4, 5) or not all(fields):
        raise ConfigurationError(f"{what}: expected NAME:ID:DLC:CYCLE_MS[:SENDER]")
    name, raw_id, raw_dlc, raw_cycle = fields[:4]
    try:
        can_id, dlc = int(raw_id, 0), int(raw_dlc)
    except ValueError:
        raise ConfigurationError(f"{what}: ID and DLC must be integers") from None
    if not 0 <= can_id <= 0x1FFFFFFF:
        raise ConfigurationError(f"{what}: ID {raw_id} is outside 0..0x1FFFFFFF")
    if not 0 <= dlc <= MAX_DLC:
        raise ConfigurationError(f"{what}: DLC {dlc} is not a CAN 2.0 data length (0..8)")
    period_ns = ms_to_ns(raw_cycle, what)
    if len(fields) == 5 and nodes is not None and fields[4] not in nodes:
        raise ConfigurationError(
            f"{what}: {fields[4]} is no node of the DBC ({', '.join(sorted(nodes))}); leave "
            "SENDER out for a node of its own")
    return BusMessage(
        name=name,
        can_id=can_id,
        extended=can_id > 0x7FF,
        dlc=dlc,
        senders=(fields[4] if len(fields) == 5 else f"({name})",),
        period_ns=period_ns,
        deadline_ns=period_ns,
        assumption="added with --add" + (", a 29-bit ID (above 0x7FF)" if can_id > 0x7FF else ""),
    )


def _check_unique(messages: list[BusMessage]) -> None:
    seen_names: set[str] = set()
    seen_ids: dict[tuple[int, bool], str] = {}
    for message in messages:
        if message.name in seen_names:
            raise ConfigurationError(f"two messages are named {message.name}")
        key = (message.can_id, message.extended)
        if key in seen_ids:
            raise ConfigurationError(
                f"{message.name} and {seen_ids[key]} share ID {message.can_id:#x}: "
                "arbitration cannot order them"
            )
        seen_names.add(message.name)
        seen_ids[key] = message.name


def parse_ticks(items: list[str], messages: list[BusMessage]) -> dict[str, int]:
    """``NODE=MS`` items as {node: tick ns}; a node that sends nothing is a one-line error."""
    senders = {sender for message in messages for sender in message.senders}
    ticks: dict[str, int] = {}
    for item in items:
        node, sep, raw = (part.strip() for part in item.partition("="))
        if not sep or not node:
            raise ConfigurationError(f"--tick-ms {item!r}: expected NODE=MS")
        if node not in senders:
            known = ", ".join(sorted(senders))
            raise ConfigurationError(f"--tick-ms {item!r}: {node} sends no message ({known} do)")
        ticks[node] = ms_to_ns(raw, f"--tick-ms {item!r}")
    return ticks


def _ms(value_ns: int | None, digits: int = 3) -> str:
    return "unbounded" if value_ns is None else f"{value_ns / NS_PER_MS:.{digits}f}"


def busload_table(load: BusLoad) -> Table:
    """One row per message, highest priority first; times in ms."""
    table = Table(box=box.SIMPLE_HEAD, pad_edge=False)
    for header in ("ID", "message", "sender", "DLC", "bits", "T", "D", "C", "J", "B", "R", "slack"):
        table.add_column(header, justify="left" if header in ("message", "sender") else "right")
    for message, response in zip(load.messages, load.responses, strict=True):
        flow = response.flow
        slack = _ms(response.slack_ns)
        style = "" if response.meets_deadline else "bold red"
        table.add_row(
            f"{message.can_id:#010x}" if message.extended else f"{message.can_id:#05x}",
            message.name + ("" if message.cyclic else " *")
            + (f" x{message.frames_per_cycle}" if message.frames_per_cycle > 1 else ""),
            ",".join(message.senders),
            str(message.dlc),
            str(frame_bits(message.dlc, extended=message.extended)),
            _ms(flow.t_ns, 1),
            _ms(flow.d_ns, 1),
            _ms(flow.c_ns),
            _ms(flow.j_ns),
            _ms(response.b_ns),
            _ms(response.r_ns),
            f"[{style}]{slack}[/{style}]" if style else slack,
        )
    return table


def print_busload(load: BusLoad, console: Console, *, title: str) -> None:
    """The table, the utilization, the assumptions and the verdict."""
    report = load.as_dict()
    console.print(f"[bold]{title}[/bold] at {load.bitrate} bit/s (Davis et al. 2007 analysis)")
    console.print(
        "times in ms: T period, D deadline, C frame, J queuing jitter, B blocking, "
        "R worst response; * sporadic"
    )
    if any(message.frames_per_cycle > 1 for message in load.messages):
        console.print("xN: N frames each cycle (E2EFramesPerCycle), queued at once: C per frame, "
                      "R the last frame's")
    console.print(busload_table(load))
    console.print(
        f"utilization {report['utilization']:.1%} "
        f"(cyclic messages {report['utilization_cyclic']:.1%})",
        highlight=False,
    )
    ticks = ", ".join(f"{node} {tick:g} ms" for node, tick in report["sender_tick_ms"].items())
    console.print(f"sender ticks: {ticks}; queue jitter {report['queue_jitter_ms']:g} ms")
    for message in load.messages:
        if message.assumption:
            console.print(
                f"- {message.name}: {message.assumption} ({message.period_ns / NS_PER_MS:g} ms)"
            )
    name, slack_ns = load.worst_slack()
    if load.schedulable:
        console.print(
            f"[green]OK[/green]: every message meets its deadline; least slack "
            f"{_ms(slack_ns)} ms ({name})"
        )
    else:
        missing = [r.flow.name for r in load.responses if not r.meets_deadline]
        console.print(f"[bold red]MISS[/bold red]: can miss the deadline: {', '.join(missing)}")
