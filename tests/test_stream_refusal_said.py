"""``odocan analyze --stream always`` says so when the streamed judge refuses a log (issue #11).

A user who asked for ``always`` asked for bounded memory: before, a refused log
(``stream_analysis.NotStreamable``) was read whole without a word. Now one line on stderr names
the log and the refusal's reason; the verdict and report stay the whole log's, and stdout
(``--report -``, ``--junit -``) stays valid. Under ``auto`` the stream is the CLI's own choice
and a refusal stays quiet (``--stream`` help). The evidence log of
``tests/test_stall_before_first_pose.py`` is one the stream refuses (its reason: ``_reason``).
"""

from __future__ import annotations

import json
import shutil
import xml.etree.ElementTree as ET
from functools import cache
from pathlib import Path

import can
import pytest

from odocan.host.cli.app import main
from odocan.host.judge import stream_analysis, stream_choice
from odocan.host.judge.stream_analysis import NotStreamable, analyze_file
from odocan.host.protocol.commands import CommandEncoder
from odocan.sim.robot import load
from odocan.sim.scenarios import get_scenario
from tests.test_stall_before_first_pose import EVIDENCE


@cache
def _reason() -> str:
    """Why the streamed judge refuses the evidence (said by ``analyze_file`` itself)."""
    with pytest.raises(NotStreamable) as refusal:
        analyze_file(EVIDENCE, load("pmir"))
    return str(refusal.value)


def _said(log: Path | str) -> str:
    """The line, with the memory the refused path takes for the log (its size:
    ``WHOLE_RSS_MB``, its slope ``REFUSED_SLOPE_OVER_WHOLE`` times steeper)."""
    base, per_mb = stream_choice.WHOLE_RSS_MB[Path(log).suffix]
    rss_mb = base + stream_choice.REFUSED_SLOPE_OVER_WHOLE * per_mb * Path(
        log).stat().st_size / 1e6
    return (f"odocan analyze: {log}: not streamable ({_reason()}): judged whole, in up to about "
            f"{rss_mb:.0f} MB of memory (the stream aims under 300 MB)")


def _analyze(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    code = main(["analyze", *args])
    out, err = capsys.readouterr()
    return code, out, err


def test_always_says_a_refused_log_is_judged_whole(capsys: pytest.CaptureFixture[str]) -> None:
    """Before: exit 0 and nothing on stderr. The report is the whole log's all the same."""
    code, out, err = _analyze(capsys, str(EVIDENCE), "--stream", "always", "--report", "-")
    assert code == 0
    assert err.splitlines().count(_said(EVIDENCE)) == 1, err
    streamed = json.loads(out)  # stdout stays the report alone
    code, out, err = _analyze(capsys, str(EVIDENCE), "--stream", "never", "--report", "-")
    assert code == 0
    assert "not streamable" not in err
    whole = json.loads(out)
    assert streamed == whole


def test_always_keeps_junit_on_stdout_valid(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = _analyze(capsys, str(EVIDENCE), "--stream", "always", "--junit", "-")
    assert code == 0
    assert _said(EVIDENCE) in err.splitlines()
    assert ET.fromstring(out).tag in ("testsuites", "testsuite")


def test_auto_falls_back_quietly(capsys: pytest.CaptureFixture[str],
                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """``auto`` made to stream this small log (its size threshold 0): the stream is tried and
    refuses it, the whole log judges it, and nothing is said of it."""
    monkeypatch.setattr(stream_choice, "stream_above_bytes", lambda suffix: 0.0)
    tried: list[object] = []
    real = stream_analysis.analyze_file

    def spied(*args: object, **kwargs: object) -> object:
        tried.append(args[0])
        return real(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(stream_analysis, "analyze_file", spied)
    code, _, err = _analyze(capsys, str(EVIDENCE))
    assert code == 0
    assert tried == [EVIDENCE]  # the stream was taken, and refused
    assert "not streamable" not in err, err


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_many_logs_say_each_refusal(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                    jobs: str) -> None:
    """Several logs (in this process, and in worker processes): one line per refused log,
    under ``always`` only."""
    logs = [tmp_path / "a.blf", tmp_path / "b.blf"]
    for log in logs:
        shutil.copyfile(EVIDENCE, log)
    names = [str(log) for log in logs]
    code, out, err = _analyze(capsys, *names, "--stream", "always", "--jobs", jobs)
    assert code == 0
    for log in logs:
        shown = next(line for line in out.splitlines() if log.name in line).split()[0]
        assert err.splitlines().count(_said(shown)) == 1, err
    code, _, err = _analyze(capsys, *names, "--stream", "never", "--jobs", jobs)
    assert code == 0
    assert "not streamable" not in err


def _config_drive(scenario: str, halted: int, after: int) -> tuple[can.Message, ...]:
    """``test_staged_apply_sweep.drive``'s re-primed stall, but the APPLY ``after`` ticks after
    it is a config's (every field staged, pmir's own values, then APPLY, in that tick)."""
    from tests.fault_rig import FaultRig, reset_then_send
    from tests.test_reprime_apply import AFTER_TICKS, REBOOT
    from tests.test_staged_reboot import PMIR

    frames = CommandEncoder().build("config", {
        "counts_per_rev": PMIR.counts_per_rev, "wheel_radius_left_m": PMIR.wheel_radius_left_m,
        "wheel_radius_right_m": PMIR.wheel_radius_right_m, "wheelbase_m": PMIR.wheelbase_m,
        "counter_bits": PMIR.counter_bits, "integrator": "exact"}).frames
    with FaultRig(scenario=get_scenario(scenario, PMIR, duration_s=60.0)) as rig:
        rig.halted = lambda k: REBOOT < k <= REBOOT + halted
        return reset_then_send(rig, REBOOT, REBOOT + halted + after,
                               [(frame.can_id, frame.data) for frame in frames],
                               REBOOT + halted + AFTER_TICKS)


@pytest.mark.parametrize("apply", ["set-pose", "config"])
def test_an_apply_just_after_a_reprimed_stall_is_one_line_then_whole(
        apply: str, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The other refusal kept (issue #11/#13: an APPLY, a set-pose's or a config's, cut the
    firmware's first pose after a re-primed stall off the life before it,
    ``acrosscut.STREAM``): under ``always`` one line naming it (before, it said "a set-pose
    cut ...: judged on the whole log): judged whole", for a config's APPLY too); under ``auto``
    made to stream, quiet; each gives the whole judge's report (a config's: its ACK, PASS)."""
    from odocan.host.judge import acrosscut
    from tests.test_staged_apply_sweep import TARGETS, drive
    from tests.test_staged_reboot import _written

    messages = (drive("spin", 400, 2, TARGETS[0]) if apply == "set-pose"
                else _config_drive("circle", 400, 2))
    log = _written(messages, tmp_path / "apply.log")
    code, out, err = _analyze(capsys, str(log), "--robot", "pmir", "--stream", "never",
                              "--report", "-")
    whole = json.loads(out)
    assert code == 0
    assert "not streamable" not in err
    assert apply != "config" or [e["kind"] for e in whole["events"]].count("config") == 1
    code, out, err = _analyze(capsys, str(log), "--robot", "pmir", "--stream", "always",
                              "--report", "-")
    assert code == 0
    said = [line for line in err.splitlines() if "not streamable" in line]
    assert said == [f"odocan analyze: {log}: not streamable ({acrosscut.STREAM}): judged whole, "
                    f"in up to about {stream_choice.refused_rss_mb(log):.0f} MB of memory (the "
                    "stream aims under 300 MB)"]
    assert "judged on the whole log" not in said[0]
    assert "config" in said[0]
    assert json.loads(out) == whole
    monkeypatch.setattr(stream_choice, "stream_above_bytes", lambda suffix: 0.0)
    code, out, err = _analyze(capsys, str(log), "--robot", "pmir", "--report", "-")
    assert code == 0
    assert "not streamable" not in err
    assert json.loads(out) == whole
