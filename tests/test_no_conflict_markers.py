"""No tracked file carries a merge's conflict markers: inside a docstring or a Markdown page they
pass ruff, mypy and every other test (one did, in ``odocan fleet``'s docstring, for a session)."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MARKER = re.compile(rb"^(<{7}|>{7})( |$)", re.MULTILINE)  # ======= alone may underline a heading


def tracked_text_files() -> list[Path]:
    out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True)
    paths = [ROOT / p for p in out.stdout.decode().split("\0") if p]
    return [p for p in paths if p.suffix in {".py", ".md", ".c", ".h", ".dbc", ".toml", ".txt"}]


def test_no_conflict_markers() -> None:
    files = tracked_text_files()
    assert len(files) > 100  # the listing worked
    marked = [str(p.relative_to(ROOT)) for p in files if p.is_file()
              and MARKER.search(p.read_bytes())]
    assert marked == []


def test_the_pattern_finds_a_marker() -> None:
    assert MARKER.search(b"text\n<<<<<<< HEAD\nours\n=======\ntheirs\n>>>>>>> branch\n")
    assert not MARKER.search(b"A heading\n=======\nx = '<' * 7\n")
