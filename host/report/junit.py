"""JUnit XML of odocan's checks, for CI servers (GitLab, Jenkins, GitHub's test reporters).

One ``<testsuite>`` per command, one ``<testcase>`` per check (on-board vs reference, vs truth,
E2E, a goal, a UMBmark bound ...); a failed check carries its figures in the ``<failure>`` message
and text, so the CI page shows what was measured against which limit.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path


@dataclass(frozen=True)
class Check:
    """One verdict: ``name`` (e.g. ``onboard_vs_reference``), passed or not, and the figures that
    decided it (``{"max_position_error_m": 3.1e-5, "limit_m": 1e-4}``)."""

    name: str
    passed: bool
    message: str = ""
    figures: dict[str, object] = field(default_factory=dict)


def junit_xml(suite: str, checks: list[Check], *, time_s: float = 0.0,
              properties: dict[str, str] | None = None) -> str:
    """The JUnit XML document of ``checks`` as one test suite named ``suite``, with the
    suite's ``properties`` (JUnit's ``<properties>``) when given."""
    import xml.etree.ElementTree as ET  # here: every command without --junit skips it

    failures = sum(not check.passed for check in checks)
    root = ET.Element("testsuites", name="odocan", tests=str(len(checks)), failures=str(failures))
    node = ET.SubElement(
        root, "testsuite", name=suite, tests=str(len(checks)), failures=str(failures),
        errors="0", skipped="0", time=f"{time_s:.3f}",
    )
    if properties:
        listed = ET.SubElement(node, "properties")
        for name, value in properties.items():
            ET.SubElement(listed, "property", name=name, value=value)
    for check in checks:
        case = ET.SubElement(node, "testcase", classname=f"odocan.{suite}", name=check.name)
        figures = "\n".join(f"{key} = {value}" for key, value in check.figures.items())
        if not check.passed:
            failure = ET.SubElement(case, "failure", message=check.message or "check failed")
            failure.text = figures
        elif figures:
            ET.SubElement(case, "system-out").text = figures
    ET.indent(root)
    return ET.tostring(root, encoding="unicode", xml_declaration=True) + "\n"


def write_junit(path: Path, suite: str, checks: list[Check], *, time_s: float = 0.0) -> None:
    """Write ``junit_xml(...)`` to ``path`` (UTF-8) in full or not at all, as ``--junit``
    (``host.outputs.write_text``: it wrote in place, and a full disk or a signal part-way cut
    an older file there); a failed write is one ``OutputError`` naming the path."""
    from odocan.host.outputs import write_text

    write_text(path, junit_xml(suite, checks, time_s=time_s), "--junit")
