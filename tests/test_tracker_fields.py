"""No live helper reaches into the live judge's private fields: outside ``host.judge.tracking``
nothing reads a ``_``-name of a ``PoseTracker`` (what a helper needs has a public, owned home: a
sub-object such as ``truths``, or a method named for what it does). The scan is of the source
(``ast``), by the names a tracker goes by: ``tracker``, ``self.tracker``, ``self._tracker``,
``telemetry.tracker``."""

from __future__ import annotations

import ast
from pathlib import Path

HOST = Path(__file__).resolve().parents[1] / "host"
ROOMS = ("judge", "mqtt", "report", "cli")
TRACKER_NAMES = frozenset({"tracker", "_tracker"})
OWNER = "judge/tracking.py"


def _names_a_tracker(node: ast.expr) -> bool:
    """``tracker``, ``_tracker`` or any ``X.tracker`` / ``X._tracker``."""
    if isinstance(node, ast.Name):
        return node.id in TRACKER_NAMES
    return isinstance(node, ast.Attribute) and node.attr in TRACKER_NAMES


def private_reads(host: Path) -> set[tuple[str, int, str]]:
    """(file under ``host``, line, expression) of each ``<tracker>._name`` outside the owner."""
    found = set()
    for room in ROOMS:
        for path in sorted((host / room).rglob("*.py")):
            name = path.relative_to(host).as_posix()
            if name == OWNER:
                continue
            tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
            for node in ast.walk(tree):
                if (isinstance(node, ast.Attribute) and node.attr.startswith("_")
                        and not node.attr.startswith("__") and _names_a_tracker(node.value)):
                    found.add((name, node.lineno, ast.unparse(node)))
    return found


def test_no_module_outside_tracking_reads_a_private_field_of_the_tracker() -> None:
    assert private_reads(HOST) == set()


def test_the_scan_sees_each_spelling_of_a_tracker(tmp_path: Path) -> None:
    (tmp_path / "judge").mkdir()
    (tmp_path / "mqtt").mkdir()
    (tmp_path / "judge" / "tracking.py").write_text("self._pos = tracker._pos\n")  # the owner
    (tmp_path / "judge" / "x.py").write_text(
        "def f(tracker, telemetry):\n"
        "    tracker._pos += 1\n"
        "    self._tracker._compare()\n"
        "    return telemetry.tracker._now_s, tracker.__class__, tracker.now_s, self._pos\n"
    )
    (tmp_path / "mqtt" / "y.py").write_text("a = self.tracker._last_pair\n")
    assert private_reads(tmp_path) == {
        ("judge/x.py", 2, "tracker._pos"),
        ("judge/x.py", 3, "self._tracker._compare"),
        ("judge/x.py", 4, "telemetry.tracker._now_s"),
        ("mqtt/y.py", 1, "self.tracker._last_pair"),
    }
