"""``bench/fleet_flat.py --parts`` splits ``cpu_s`` (the process's CPU while the fleet's clock
ran) into its parts; in real time with releases skipped it printed "the rest -86.7 us" (50
robots, 228 of 300 releases skipped): the bridge's frame handling was counted after the clock
stopped too (its final drain of the frames it fell behind on, 47 of its 52 us per
robot-release), which ``cpu_s`` leaves out. The parts now count while the clock runs only, and
what came after is said apart. Figures here come from a test clock (one second a timed call),
not from timings."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

BENCH = Path(__file__).resolve().parent.parent / "bench" / "fleet_flat.py"


def _bench() -> ModuleType:
    """The bench script as a module; the path entries and ``fleet`` (bench/fleet.py) it adds
    taken out again, so that no other test imports a bench file by a bare name."""
    path, had_fleet = list(sys.path), "fleet" in sys.modules
    spec = importlib.util.spec_from_file_location("fleet_flat_under_test", BENCH)
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    finally:
        sys.path[:] = path
        if not had_fleet:
            sys.modules.pop("fleet", None)
    return module


def test_the_bridges_drain_after_the_clock_is_no_part_of_cpu_s() -> None:
    parts = _bench().Parts()
    seconds = iter(range(1000))
    parts.clock = lambda: float(next(seconds))  # each timed call: 1 s
    step = parts.timed_part(lambda: None, "step")
    handle = parts.timed_part(lambda: None, "handle")
    parts.clocked = True  # the clock runs: 5 s of cpu_s, 2 s of step, 1 s of frame handling
    step()
    step()
    handle()
    parts.clocked = False  # the clock stopped: the bridge drains what it fell behind on
    handle()
    handle()
    handle()
    line = parts.line(cpu_s=5.0, robot_ticks=1_000_000)  # 1 s: 1 us per robot-tick
    first, _mqtt, after = line.splitlines()
    assert first.startswith("  step 2.0, bridge frame handling 1.0, young GC passes 0.0, the rest "
                            "2.0 us;"), first
    assert after == ("  after the clock (not in cpu_s), us per robot-tick: step 0.0, bridge frame "
                     "handling (its drain) 3.0, young GC passes 0.0")
