"""The firmware's latched REASONs in a person's words (ODOM_STATUS REASON, ERROR_MASK bits): why
the firmware stays DEGRADED and what ends it, one line each, for the monitor's verdict and the
firmware events the monitor, the MQTT bridge and ``analyze`` share (``host.judge.statuslatch``).
The other REASONs end by themselves and are shown by their DBC names alone."""

from __future__ import annotations

from odocan.firmware.uncertainty import UNCERTAINTY_TOLERANCE_UM

REASON_WORDS = {
    "COUNTER_RESET": "the encoder counters restarted, the motion across it is not in the pose; "
                     "DEGRADED until a set-pose",
    "POSE_UNCERTAIN": "steps merged across lost encoder periods may have put the pose more than "
                      f"{UNCERTAINTY_TOLERANCE_UM // 1000} mm off (their path is unknowable); "
                      "DEGRADED until a set-pose",
}


def reason_text(name: str) -> str:
    """``name`` (a REASON or ERROR_MASK bit name), with its words when it has some."""
    words = REASON_WORDS.get(name)
    return f"{name}: {words}" if words else name
