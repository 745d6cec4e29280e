"""The latched REASONs in words (issue #11 point 5): POSE_UNCERTAIN and COUNTER_RESET keep the
firmware DEGRADED until a set-pose, so the monitor's verdict and the firmware events (shared by
the monitor, the MQTT bridge's retained status and ``analyze``) say why and what ends it, by the
DBC name and in one line; the others are shown by their names alone.

The summaries come from a lockstep run (the 2 s MCU stall of ``tests/test_health_rig``: a merged
step past the tolerance), decoded by the monitor as a person would see it.
"""

from __future__ import annotations

from typing import Any

from odocan.firmware.errors import ErrorFlag
from odocan.host.judge.statuslatch import StatusLatch
from odocan.sim.contract import database
from tests.test_health_rig import run_stall

STATUS = database().get_message_by_name("ODOM_STATUS")
RAW = {str(n): int(v) for v, n in (STATUS.get_signal_by_name("REASON").choices or {}).items()}


def _said(words: str) -> None:
    """One line: the cause in a person's words and what ends it."""
    assert "\n" not in words
    assert "until a set-pose" in words


def test_a_latched_reason_is_said_in_words_in_the_firmware_events() -> None:
    latch = StatusLatch()
    latch.observe(1.0, 1, RAW["NONE"], 0)  # OK
    events: list[dict[str, Any]] = latch.observe(
        1.1, 2, RAW["POSE_UNCERTAIN"], int(ErrorFlag.POSE_UNCERTAIN))  # DEGRADED
    state, bit = events
    assert state["reason"] == "POSE_UNCERTAIN"  # the name, as the DBC gives it
    assert state["detail"].startswith("state OK -> DEGRADED (reason POSE_UNCERTAIN: ")
    assert "merged" in state["detail"]
    assert "50 mm" in state["detail"]
    _said(state["detail"])
    assert bit["bit"] == "POSE_UNCERTAIN"
    _said(bit["detail"])
    reset = StatusLatch()
    reset.observe(1.0, 1, RAW["NONE"], 0)
    (changed, _) = reset.observe(1.1, 2, RAW["COUNTER_RESET"], int(ErrorFlag.COUNTER_RESET))
    assert "counters restarted" in changed["detail"]
    _said(changed["detail"])
    short = StatusLatch()
    short.observe(1.0, 1, RAW["NONE"], 0)
    (timeout, _) = short.observe(1.1, 2, RAW["ENCODER_TIMEOUT"], int(ErrorFlag.ENCODER_TIMEOUT))
    assert timeout["detail"] == "state OK -> DEGRADED (reason ENCODER_TIMEOUT)"  # ends by itself


def test_the_monitor_says_pose_uncertain_by_name_and_why() -> None:
    watch, figures = run_stall()
    assert figures["states"][-1] == ("DEGRADED", "POSE_UNCERTAIN")
    end_s = watch.verdicts[-1][0]
    health = watch.monitor.health(end_s)
    assert health["state"] == "DEGRADED"
    (why,) = health["why"]
    assert why.startswith("firmware reports DEGRADED (POSE_UNCERTAIN: ")
    assert "50 mm" in why
    _said(why)
    assert watch.monitor.status["reason"] == "POSE_UNCERTAIN"
    bits = [e for e in health["firmware_events"] if e["kind"] == "error_bit"
            and e["bit"] == "POSE_UNCERTAIN"]
    assert len(bits) == 1
    _said(bits[0]["detail"])
