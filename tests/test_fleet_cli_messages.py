"""What ``odocan fleet`` says (#13): its help is the fleet it is now, the start line counts one
robot as one, and the live and final deadline figures say which ratio they are."""

from __future__ import annotations

import argparse

import pytest

from odocan.host.cli.app import build_parser
from odocan.host.cli.subparsers import fleet
from odocan.host.report.progress import Progress


def _fleet_parser() -> argparse.ArgumentParser:
    parser = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    sub: argparse.ArgumentParser = action.choices["fleet"]
    return sub


def test_fleet_help_says_workers_shards_and_the_default_transport() -> None:
    sub = _fleet_parser()
    text = " ".join(sub.format_help().split())
    assert "in one process" not in text
    assert "virtual CAN channels" not in text
    description = sub.description or ""
    for said in ("--workers", "--shard K/N", "odocan transport", "--transport virtual"):
        assert said in description, said


def test_the_start_line_counts_one_robot_as_one(capsys: pytest.CaptureFixture[str]) -> None:
    fleet._say_started(1, None)
    fleet._say_started(3, None)
    lines = capsys.readouterr().err.splitlines()
    assert lines[0].startswith("fleet: 1 robot running;"), lines[0]
    assert lines[1].startswith("fleet: 3 robots running;"), lines[1]


def test_the_progress_line_says_its_ratio_is_over_every_worker() -> None:
    bar = Progress(label="x", total=1.0)
    fleet._relabel(bar, "fleet of 4 robots", 1000, 451)
    assert "(0.4510 overall)" in bar.label, bar.label
    assert "all workers 451 of 1000 ticks late" in bar.label, bar.label


def test_the_summary_says_the_ratio_is_the_worst_workers_and_gives_the_overall(
    capsys: pytest.CaptureFixture[str],
) -> None:
    def worker(first: str, ratio: float) -> dict[str, object]:
        return {"first_robot": first, "deadline_miss_ratio": ratio}

    report = {"robots": 2, "first_robot": "robot001", "ticks": 2000, "late_ticks": 903,
              "deadline_miss_ratio": 0.4854, "max_lateness_ms": 12.0, "broker": None,
              "workers": [worker("robot001", 0.4176), worker("robot002", 0.4854)],
              "per_robot": {"robot001": {"verdict": "PASS"}, "robot002": {"verdict": "PASS"}}}
    fleet._print_summary(report, [])
    first = capsys.readouterr().out.splitlines()[0]
    assert "deadline_miss_ratio 0.4854 (the worst worker's, the verdict's; overall 0.4515;" \
        in first, first
