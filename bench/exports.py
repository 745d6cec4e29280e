"""Export cost: ``--parquet`` and ``--mcap`` of one lockstep drive, against the analysis itself.

Runs the lockstep rig for ``--seconds`` simulated seconds (default 600: 216 000 frames), analyses
the frames, then times ``host.io.parquet.write_parquet`` and ``host.io.mcap.write_mcap`` into a
temporary directory and prints seconds, frames/s and sizes, and the time to read them back
(DuckDB's max position error over the Parquet; the ``mcap`` reader over every message). Prints
figures; asserts nothing. Run: ``.venv/bin/python bench/exports.py [--seconds S]``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from odocan.host.io.logs import FrameCollector  # noqa: E402
from odocan.host.io.mcap import write_mcap  # noqa: E402
from odocan.host.io.parquet import write_parquet  # noqa: E402
from odocan.host.judge.analysis import analyze  # noqa: E402
from odocan.sim.rig import LockstepRig, RigConfig  # noqa: E402
from odocan.sim.robot import load  # noqa: E402


def rss_mb() -> float:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def timed(label: str, frames: int, func: object, *args: object) -> object:
    start = time.perf_counter()
    result = func(*args)  # type: ignore[operator]
    seconds = time.perf_counter() - start
    print(f"{label:<34} {seconds:7.3f} s  {frames / seconds / 1e3:8.1f} k frames/s  "
          f"max RSS so far {rss_mb():.0f} MB")
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=600.0)
    seconds = parser.parse_args().seconds
    robot = load("pmir")
    collector = FrameCollector()
    with LockstepRig(RigConfig(robot, "exact", "random", 1), [collector]) as rig:
        rig.run(seconds)
    frames = collector.arrays()
    n = len(frames)
    print(f"{seconds:g} s simulated, {n} frames")
    analysis = timed("analyze", n, analyze, frames, robot)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        timed("write_parquet", n, write_parquet, out / "pq", frames, analysis)
        count = timed("write_mcap", n, write_mcap, out / "run.mcap", frames, analysis)
        size_pq = sum(p.stat().st_size for p in (out / "pq").iterdir())
        size_mcap = (out / "run.mcap").stat().st_size
        print(f"sizes: Parquet {size_pq / 1e6:.2f} MB (11 files), MCAP {size_mcap / 1e6:.2f} MB "
              f"({count} messages)")
        import duckdb
        from mcap.reader import make_reader

        query = f"select max(position_error_m) from '{out / 'pq' / 'series.parquet'}'"
        timed("DuckDB max(position_error_m)", n, lambda: duckdb.sql(query).fetchall())

        def read_all() -> int:
            with (out / "run.mcap").open("rb") as stream:
                return sum(1 for _ in make_reader(stream).iter_messages())

        timed("mcap reader, every message", n, read_all)


if __name__ == "__main__":
    main()
