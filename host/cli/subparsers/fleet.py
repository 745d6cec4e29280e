"""``odocan fleet``: N independent robots in real time, bridged to MQTT.

Each robot is the lockstep rig's set of nodes on its own channel of the in-process ``odocan``
transport (``--transport virtual``: python-can's; scenario ``random`` with seed ``--seed + i``;
``-n/--count`` robots, ``--robot`` their profile); a timer loop steps them every 10 ms and accounts
its deadlines; the bridge publishes every robot under ``odocan/robotNNN/`` (``host.mqtt.topics``)
and judges its pose against the float64 reference. ``--workers W`` spreads the robots over W
processes, each with its own loop and MQTT connections; ``--shard K/N`` runs this machine's part of
a fleet of N machines on one broker (robot ids and seeds numbered across shards:
``host.mqtt.shards``). Without ``--broker`` an embedded amqtt broker runs in a process of its own,
on ``--port`` or a free port; its URL is printed at the start (``odocan monitor --broker URL``
watches; ``--foxglove [PORT]`` serves every robot live to Foxglove: ``host.mqtt.foxglove_fleet``).
``--report`` writes the JSON contract of ``host.mqtt.fleetrun`` (``workers`` added by
``host.mqtt.shards``) with the run's verdict on top: ``passed`` and ``failures`` (each threshold
broken, the exit line's words; ``passed`` false too for a run a signal stopped). The exit line
says PASS, or FAIL (UNJUDGED when no robot FAILed and the loop kept its deadlines: robots not
judged) and every threshold broken: exit 0, or 1 when ``deadline_miss_ratio`` exceeds
``--max-miss-ratio`` or a robot's pose is out of tolerance or not judged; a run a signal stopped
exits as the signal ends a process (143 for SIGTERM), never 0 or 1.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time
from collections import Counter
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from odocan.host import accel
from odocan.host.cli.firmware_choice import AUTO_FIRMWARE, FIRMWARE_CHOICES, resolve_firmware
from odocan.host.cli.options import SEED_LIMIT, add_seed_argument, float_in, int_in
from odocan.host.io.export import FOXGLOVE_PORT
from odocan.host.mqtt.broker import BrokerURL
from odocan.host.mqtt.fleetjudge import DEFAULT_MAX_MISS_RATIO
from odocan.host.mqtt.fleetrun import FleetRun, failures, run_verdict
from odocan.host.mqtt.options import (
    add_mqtt_arguments,
    bridge_options,
    broker_url,
    configure_logging,
)
from odocan.host.mqtt.shards import Shard, embedded_broker, run_sharded
from odocan.host.outputs import check_writable, write_text
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.protocol.secoc import load_secoc_key
from odocan.host.report.foxglove_options import HOST, port_number
from odocan.host.report.progress import Progress, wall_clock_progress
from odocan.host.stopped import stop_code, stopped_text
from odocan.sim import robot
from odocan.sim.contract import read_as
from odocan.sim.e2efacts import require_firmware_follows
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.fleet import FleetConfig, robot_name
from odocan.sim.rig import INTEGRATORS, TRANSPORTS, firmware_params
from odocan.sim.scenarios import SCENARIOS

if TYPE_CHECKING:
    from collections.abc import Iterable

    from odocan.host.mqtt.foxglove_fleet import FleetFoxglove

FLEET_MAX_ROBOTS = 500  # one 2-core machine holds about 45 in real time (README, bench/fleet.py)
FLEET_MAX_DURATION_S = 86400.0
FLEET_MAX_WORKERS = 64


def add_subparser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``odocan fleet``."""
    parser = subparsers.add_parser(
        "fleet",
        help="run N robots in real time, bridged to MQTT",
        description="Run N independent robots (motor controller, truth, scenario, firmware, "
        "each robot on its own bus of the in-process odocan transport; --transport virtual: "
        "python-can's) in real time, bridged to MQTT, spread over --workers processes (one "
        "real-time loop and MQTT connections each); --shard K/N runs this machine's part of a "
        "fleet of N machines on one --broker.",
    )
    _add_arguments(parser)
    parser.set_defaults(func=_do_fleet)


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "-n",
        "--count",
        "--robots",
        dest="count",
        type=int_in(1, FLEET_MAX_ROBOTS),
        default=3,
        metavar="N",
        help=f"how many robots, 1 .. {FLEET_MAX_ROBOTS} (--robots: deprecated alias) "
        "(default: %(default)s)",
    )
    parser.add_argument(
        "--duration",
        type=float_in(0.0, FLEET_MAX_DURATION_S, lo_open=True),
        default=10.0,
        metavar="SECONDS",
        help=f"WALL-CLOCK seconds to run, at most {FLEET_MAX_DURATION_S:g} (default: %(default)s)",
    )
    parser.add_argument(
        "--report", type=Path, metavar="PATH", help="write the JSON report (default: none;"
        " - for stdout: the summary then goes to stderr)"
    )
    parser.add_argument(
        "--robot", default="pmir", help="profile of every robot, name or TOML path (default: pmir)"
    )
    parser.add_argument(
        "--integrator", choices=INTEGRATORS, default="exact", help="on-board integrator"
    )
    parser.add_argument("--scenario", choices=SCENARIOS, default="random", help="driving scenario")
    parser.add_argument(
        "--transport",
        choices=TRANSPORTS,
        default="odocan",
        help="python-can interface of each robot's own bus (default: odocan, the lean "
        "in-process transport; virtual: python-can's, same frames)",
    )
    parser.add_argument(
        "--firmware", choices=FIRMWARE_CHOICES, default=AUTO_FIRMWARE,
        help="every board's firmware: python (firmware/) or c (firmware/c, built with make on "
        "first use; bit-exact, a third less CPU per fleet step); auto: c when it builds and "
        "loads, python otherwise (the start line says which, and why) (default: auto)",
    )
    add_seed_argument(parser, "robot i drives with seed SEED + i")
    parser.add_argument(
        "--max-miss-ratio",
        type=float_in(0.0, 1.0),
        default=DEFAULT_MAX_MISS_RATIO,
        metavar="RATIO",
        help="exit 1 above this deadline_miss_ratio, 0 .. 1 (default: %(default)s)",
    )
    parser.add_argument(
        "--workers",
        type=int_in(1, FLEET_MAX_WORKERS),
        default=1,
        metavar="W",
        help="processes to spread this machine's robots over, 1 .. the robots (default: 1)",
    )
    parser.add_argument(
        "--shard",
        type=_shard,
        default=Shard(),
        metavar="K/N",
        help="run part K of N of the fleet (N machines, one --broker; robot ids and seeds "
        "count across the parts) (default: 1/1)",
    )
    parser.add_argument(
        "--port",
        type=int_in(1, 65535),
        metavar="PORT",
        help="the embedded broker's 127.0.0.1 port (default: a free one); not with --broker",
    )
    parser.add_argument(
        "--secoc-key",
        type=Path,
        metavar="PATH",
        help="the fleet's SecOC key (16 raw bytes or 32 hex digits; not the TLS --key): each "
        "robot's firmware verifies its commands with its own key derived from it, which its "
        "bridge signs with (docs/secoc.md) (default: no SecOC)",
    )
    parser.add_argument(
        "--accel", action="store_true",
        help="the workers' per-frame path (the bridge's judges) compiled with mypyc (needs "
        "mypy and a C compiler; built once per version of the sources into "
        "~/.cache/odocan/accel: minutes; one line on stderr and pure Python when it cannot be; "
        "ODOCAN_ACCEL=1 does the same for any command) (default: pure Python)",
    )
    add_mqtt_arguments(parser)
    _add_foxglove_argument(parser)


def _shard(text: str) -> Shard:
    """An argparse ``type``: ``K/N``."""
    try:
        return Shard.parse(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _do_fleet(args: argparse.Namespace) -> int:
    if args.seed + args.count > SEED_LIMIT:
        raise ConfigurationError(
            f"--seed {args.seed} + --count {args.count}: the last robot's seed must be < 2^32"
        )
    first, robots = args.shard.robots(args.count)
    if args.workers > robots:
        raise ConfigurationError(
            f"--workers {args.workers}: more workers than robots to run ({robots})"
        )
    check_writable(args.report, "--report")
    with read_as(default_plan()):  # the robots' firmware speaks the DBC sims and judges read
        require_firmware_follows()
    broker = broker_url(args)
    if broker is not None and args.port is not None:
        raise ConfigurationError("--port is the embedded broker's: --broker names its own port")
    if broker is None and args.shard.count > 1:  # a private broker: no other shard meets it
        raise ConfigurationError("--shard needs --broker: the shards of one fleet meet on one "
                                 "broker")
    profile = robot.load(args.robot)
    choice = resolve_firmware(args.firmware, args.secoc_key is not None,
                              firmware_params(profile, args.integrator))
    fleet = FleetConfig(
        robots=args.count,
        robot=profile,
        integrator=args.integrator,
        scenario=args.scenario,
        seed=args.seed,
        secoc_key=None if args.secoc_key is None else load_secoc_key(args.secoc_key),
        transport=args.transport,
        firmware=choice.firmware,
    ).shard(first, robots)
    run = FleetRun(fleet=fleet, duration_s=args.duration, broker=broker,
                   max_miss_ratio=args.max_miss_ratio, **bridge_options(args))
    debug = getattr(args, "debug", False)
    configure_logging(debug)
    names = [robot_name(fleet.first + i) for i in range(fleet.robots)]
    with _accelerated(args.accel) as compiled:
        said = choice.said + ("; compiled per-frame path (mypyc)" if compiled else "")
        spawn = compiled and not accel.active()  # one worker too: its own, compiled, imports
        if broker is None:
            with embedded_broker(args.port) as url, _foxglove(args, url, names):
                report = _run(replace(run, broker=url), args.workers, debug, said, spawn)
            report["embedded_broker"] = True
        else:
            with _foxglove(args, broker, names):
                report = _run(run, args.workers, debug, said, spawn)
    broken = failures(report, args.max_miss_ratio)
    report.update(passed=not broken and not report.get("stopped"), failures=broken)
    _print_summary(report, broken, run_verdict(report, args.max_miss_ratio))
    if args.report is not None:
        write_text(args.report, json.dumps(report, indent=2) + "\n", "--report")
    if report.get("stopped"):
        return stop_code(report["stopped"])  # not the fleet it was asked for: never 0
    return 1 if broken else 0


def _add_foxglove_argument(parser: argparse.ArgumentParser) -> None:
    """``--foxglove [PORT]``: the Foxglove SDK is imported only when it is given."""
    parser.add_argument(
        "--foxglove", nargs="?", type=port_number, const=FOXGLOVE_PORT, metavar="PORT",
        help=f"serve every robot's poses, transforms and errors live to Foxglove on "
        f"{HOST}:PORT (default {FOXGLOVE_PORT}; 0: any free port), from the fleet's MQTT "
        "telemetry",
    )


def _foxglove(
    args: argparse.Namespace, broker: BrokerURL, robots: Iterable[str]
) -> contextlib.AbstractContextManager[FleetFoxglove | None]:
    """``serve_fleet_foxglove`` with ``--foxglove``; else a context that imports nothing."""
    if args.foxglove is None:
        return contextlib.nullcontext(None)
    from odocan.host.mqtt.foxglove_fleet import serve_fleet_foxglove

    return serve_fleet_foxglove(args, broker, robots)


def _accelerated(asked: bool) -> contextlib.AbstractContextManager[bool]:
    """``--accel``: ``host.accel.for_children`` (the workers compiled); else pure Python, or
    compiled already (``ODOCAN_ACCEL=1``: this process and its workers)."""
    if asked:
        return accel.for_children()
    return contextlib.nullcontext(bool(accel.active()))


def _run(run: FleetRun, workers: int, debug: bool, firmware: str = "",
         spawn: bool = False) -> dict[str, Any]:
    """The fleet under a live progress line (elapsed, ETA, the late ticks so far), drawn from
    when the clock starts (the start line first), not while the workers and broker start."""
    label = f"fleet of {robots_text(run.fleet.robots)}"
    with wall_clock_progress(label, run.duration_s) as bar:
        drawn, bar.enabled = bar.enabled, False

        def started(robots: int, url: BrokerURL | None) -> None:
            _say_started(robots, url, firmware)
            bar.started = time.monotonic()
            bar.enabled = drawn

        return run_sharded(
            run,
            workers,
            on_start=started,
            debug=debug,
            spawn=spawn,
            on_progress=lambda ticks, late: _relabel(bar, label, ticks, late),
        )


def _relabel(bar: Progress, label: str, ticks: int, late: int) -> None:
    """The progress line's label with the deadline figures so far, summed over every worker
    (the summary's ``deadline_miss_ratio`` is the worst worker's: it names both)."""
    bar.label = (f"{label}, all workers {late} of {ticks} ticks late "
                 f"({late / max(ticks, 1):.4f} overall)")


def _print_summary(report: dict[str, Any], broken: list[str], word: str = "FAIL") -> None:
    """The summary line, per-robot verdict counts, then PASS, or ``word`` (FAIL, UNJUDGED:
    ``fleetrun.run_verdict``) with every reason."""
    verdicts = Counter(str(r.get("verdict")) for r in report["per_robot"].values())
    workers = len(report.get("workers", [])) or 1
    overall = report["late_ticks"] / max(report["ticks"], 1)
    last = list(report["per_robot"])[-1]
    print(
        f"fleet: {robots_text(report['robots'])}, {report['first_robot']}..{last}, "
        f"{workers} worker(s), "
        f"{report['ticks']} ticks, deadline_miss_ratio {report['deadline_miss_ratio']:.4f} "
        f"(the worst worker's, the verdict's; overall {overall:.4f}; worst tick "
        f"{report['max_lateness_ms']:.1f} ms late), broker {report['broker']}"
    )
    print("poses: " + ", ".join(f"{n} {v}" for v, n in sorted(verdicts.items())))
    verdict = f"{word}: " + "; ".join(broken) if broken else "PASS"
    if report.get("stopped"):
        verdict = f"{stopped_text(report['stopped'])}: partial run {verdict}"
    print(verdict)
    sys.stdout.flush()


def _say_started(robots: int, url: BrokerURL | None, firmware: str = "") -> None:
    """One line on stderr when the clock starts: how many robots, and where to watch them
    (``odocan monitor --broker URL``), and the firmware (``FirmwareChoice.said``)."""
    where = f", telemetry on {url}" if url is not None else ""
    which = f"; {firmware}" if firmware else ""
    print(
        f"fleet: {robots_text(robots)} running{where}{which}; Ctrl-C or SIGTERM stops and "
        "reports",
        file=sys.stderr,
        flush=True,
    )


def robots_text(robots: int) -> str:
    """``1 robot``, ``3 robots``."""
    return f"{robots} robot{'' if robots == 1 else 's'}"
