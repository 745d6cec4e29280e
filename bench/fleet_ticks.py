"""The anatomy of a real-time fleet's ticks, from the per-tick trace (``host.mqtt.ticktrace``).

    ODOCAN_TICK_TRACE=/tmp/ticks .venv/bin/python bench/fleet.py --robots 100 --workers 2 \
        --only mosquitto --trial-s 30 --firmware c
    .venv/bin/python bench/fleet_ticks.py /tmp/ticks [--top 15]

Per worker file: the median, 99th percentile and largest thread CPU (us) of each part of the
loop thread's time (``between`` the ticks: the event loop's MQTT and bridge work; ``step``;
``batch``; ``gc``) and the process CPU per tick; then the CPU of the loop's work between ticks
by what ran in it (pose, status, rates publications, the command reader's hand-overs, progress
reports): which periodic work makes the heavy ticks; then the late ticks and the ``--top``
heaviest ticks (loop-thread CPU from the previous tick's end to this one's), each with its parts
and what ran before it. On a loaded machine wall times lie (other processes run meanwhile):
compare the CPU columns; a late tick whose CPU is at the median was late for the machine's load.
``runq`` is the time the loop thread waited for a CPU (another process had it); the slow handles
(by name: how many, their CPU, how many came before a late tick, the frames each judged) are the
work a tick waited behind: the frames judged per handle do not depend on the load.
"""

from __future__ import annotations

import argparse
import json
import statistics
from collections import defaultdict
from pathlib import Path
from typing import Any

PARTS = ("between", "step", "batch", "gc")
# the fleet's clock task (its step after the sleep runs the tick: the trace's parts time it)
OWN_TASKS = ("task run_fleet", "task _work", "task main")


def quantile(values: list[float], q: float) -> float:
    """The ``q`` quantile of ``values`` (nearest rank; 0.0 when empty)."""
    if not values:
        return 0.0
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def cpu_us(row: dict[str, Any]) -> float:
    """The loop thread's CPU for a tick and the loop's work before it (us)."""
    return float(sum(row.get(f"{part}_cpu_us", 0.0) for part in PARTS))


def kinds(row: dict[str, Any]) -> str:
    """What the loop ran before the tick, as ``leaf*count`` (``-`` for nothing counted)."""
    ran = row.get("ran", {})
    return " ".join(f"{k}*{n}" for k, n in sorted(ran.items())) or "-"


def describe(row: dict[str, Any]) -> str:
    """One tick's line: its lateness, each part's CPU/wall (us) and what ran before it."""
    parts = " ".join(f"{p} {row.get(f'{p}_cpu_us', 0):.0f}/{row.get(f'{p}_wall_us', 0):.0f}"
                     for p in PARTS)
    slow = " ".join(f"<{h[0]} {h[1]}/{h[2]} f{h[3] if len(h) > 3 else '?'}>"
                    for h in row.get("slow", []) if h[0] not in OWN_TASKS)
    return (f"  k {row['k']:5d} late {row['late_ms']:6.2f} ms "
            f" runq {row.get('runq_wait_us', 0):5.0f}"
            f"  cpu {cpu_us(row):6.0f} "
            f"proc {row['proc_cpu_us']:6.0f}  [{parts}] gc_n {row.get('gc_n', 0)}  {kinds(row)}"
            + (f"  slow {slow}" if slow else ""))


def slow_handles(rows: list[dict[str, Any]]) -> None:
    """The loop's slow handles (``host.mqtt.ticktrace``'s ``slow``) by name: how many, their
    median and largest thread CPU (us), and how many came just before a late tick."""
    cpu: dict[str, list[float]] = defaultdict(list)
    frames: dict[str, list[int]] = defaultdict(list)
    before_late: dict[str, int] = defaultdict(int)
    for row in rows:
        for name, handle_cpu, _wall, *fed in row.get("slow", []):
            if name in OWN_TASKS:
                continue
            cpu[name].append(handle_cpu)
            frames[name].append(fed[0] if fed else 0)
            before_late[name] += row["late_ms"] > 5
    if not cpu:
        return
    print("  slow loop handles (count, median / max CPU us, before a late tick):")
    for name, values in sorted(cpu.items(), key=lambda kv: -max(kv[1])):
        print(f"    {name[:40]:40s} {len(values):5d} {statistics.median(values):7.0f} "
              f"{max(values):7.0f}  {before_late[name]:5d}  frames judged median "
              f"{statistics.median(frames[name]):5.0f} max {max(frames[name]):5d}")


def by_periodic(rows: list[dict[str, Any]]) -> dict[str, list[float]]:
    """The ``between`` CPU (us) of the ticks, grouped by the periodic work that ran before."""
    groups: dict[str, list[float]] = defaultdict(list)
    for row in rows:
        ran = row.get("ran", {})
        key = "+".join(sorted(k for k in ran if k not in ("pose", "reference", "error",
                                                           "truth"))) or "poses only"
        groups[key].append(row.get("between_cpu_us", 0.0))
    return groups


def report(path: Path, top: int) -> None:
    """Print one worker's anatomy (see the module docstring)."""
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    rows = rows[1:]  # the first tick has no ``between``
    print(f"{path.name}: {len(rows)} ticks, {sum(r['late_ms'] > 5 for r in rows)} late")
    for part in PARTS:
        cpu = [r.get(f"{part}_cpu_us", 0.0) for r in rows]
        wall = [r.get(f"{part}_wall_us", 0.0) for r in rows]
        print(f"  {part:8s} cpu median {statistics.median(cpu):7.0f} p99 {quantile(cpu, .99):7.0f}"
              f" max {max(cpu):7.0f} | wall median {statistics.median(wall):7.0f} "
              f"p99 {quantile(wall, .99):7.0f} max {max(wall):7.0f}")
    runq = [r.get("runq_wait_us", 0.0) for r in rows]
    print(f"  runq wait median {statistics.median(runq):7.0f} p99 {quantile(runq, .99):7.0f} "
          f"max {max(runq):7.0f} (us the loop thread was runnable, not running, per tick)")
    proc = [r["proc_cpu_us"] for r in rows]
    print(f"  process  cpu median {statistics.median(proc):7.0f} p99 {quantile(proc, .99):7.0f}"
          f" max {max(proc):7.0f}")
    print("  loop work between ticks by what ran (ticks, median / p99 / max CPU us):")
    for key, values in sorted(by_periodic(rows).items(), key=lambda kv: -len(kv[1])):
        print(f"    {key:40s} {len(values):5d}  {statistics.median(values):6.0f} "
              f"{quantile(values, .99):6.0f} {max(values):6.0f}")
    slow_handles(rows)
    late = [r for r in rows if r["late_ms"] > 5]
    print(f"  late ticks ({len(late)}), first 15:")
    for row in late[:15]:
        print(describe(row))
    print(f"  the {top} heaviest ticks by loop-thread CPU:")
    for row in sorted(rows, key=cpu_us, reverse=True)[:top]:
        print(describe(row))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("--top", type=int, default=15)
    args = parser.parse_args()
    files = sorted(args.folder.glob("ticks-*.jsonl"))
    if not files:
        parser.exit(2, f"fleet_ticks: no ticks-*.jsonl in {args.folder}\n")
    for path in files:
        report(path, args.top)


if __name__ == "__main__":
    main()
