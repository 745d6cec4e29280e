"""``odocan busload``: the table, the JSON report, the what-ifs and every kind of bad input.

The expected figures are worked by hand from the frame length (135 bits for 8 data bytes, 11-bit
ID: 270 us at 500 kbit/s) and the DBC's cycle times; the analysis itself is proven against a
simulation in tests/test_busload.py.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from odocan.host.cli.app import main
from tests.test_cli_run import assert_usage_error, run_cli

EXPECTED_500K = """\
odocan busload: dbc/odocan.dbc at 500000 bit/s (Davis et al. 2007 analysis)
times in ms: T period, D deadline, C frame, J queuing jitter, B blocking, R worst response; * sporadic
xN: N frames each cycle (E2EFramesPerCycle), queued at once: C per frame, R the last frame's

    ID   message           sender          DLC   bits        T        D       C       J       B       R     slack
 ────────────────────────────────────────────────────────────────────────────────────────────────────────────────
 0x100   WHEEL_ENCODERS    MOTOR_CTRL        8    135     10.0     10.0   0.270   0.000   0.270   0.540     9.460
 0x110   MOTOR_CMD         ODOM_MCU,HOST     8    135     20.0     20.0   0.270   0.000   0.270   0.810    19.190
 0x200   ODOM_POSE_X       ODOM_MCU          8    135     20.0     20.0   0.270   0.000   0.270   1.080    18.920
 0x201   ODOM_POSE_Y       ODOM_MCU          8    135     20.0     20.0   0.270   0.000   0.270   1.350    18.650
 0x202   ODOM_TWIST        ODOM_MCU          8    135     20.0     20.0   0.270   0.000   0.270   1.620    18.380
 0x280   NAV_GOAL *        HOST              8    135     10.0     10.0   0.270   0.000   0.270   1.890     8.110
 0x281   NAV_STATUS        ODOM_MCU          8    135    100.0    100.0   0.270   0.000   0.270   2.160    97.840
 0x300   ODOM_SET_POSE *   HOST              8    135     10.0     10.0   0.270   0.000   0.270   2.430     7.570
 0x301   ODOM_CONFIG *     HOST              8    135     10.0     10.0   0.270   0.000   0.270   2.700     7.300
 0x302   ODOM_ACK *        ODOM_MCU          8    135     10.0     10.0   0.270   0.000   0.270   2.970     7.030
 0x303   ODOM_AUTH *       HOST              8    135     10.0     10.0   0.270   0.000   0.270   3.240     6.760
 0x304   ODOM_FRESHNESS    ODOM_MCU          8    135   1000.0   1000.0   0.270   0.000   0.270   3.510   996.490
 0x380   ODOM_STATUS x2    ODOM_MCU          8    135    100.0    100.0   0.270   0.000   0.270   4.050    95.950
 0x700   SIM_TRUTH x3      SIM               8    135    100.0    100.0   0.270   0.000   0.000   4.590    95.410

utilization 23.2% (cyclic messages 9.7%)
sender ticks: HOST 20 ms, MOTOR_CTRL 10 ms, ODOM_MCU 20 ms, SIM 100 ms; queue jitter 0 ms
- NAV_GOAL: no cycle time: sporadic, min inter-arrival = the DBC's shortest cycle time (10 ms)
- ODOM_SET_POSE: no cycle time: sporadic, min inter-arrival = the DBC's shortest cycle time (10 ms)
- ODOM_CONFIG: no cycle time: sporadic, min inter-arrival = the DBC's shortest cycle time (10 ms)
- ODOM_ACK: no cycle time: sporadic, min inter-arrival = the DBC's shortest cycle time (10 ms)
- ODOM_AUTH: no cycle time: sporadic, min inter-arrival = the DBC's shortest cycle time (10 ms)
OK: every message meets its deadline; least slack 6.760 ms (ODOM_AUTH)
"""  # noqa: E501

# Three nodes; FAST is cyclic, SLOW carries a deadline tighter than its cycle, EVENT has a
# GenMsgDelayTime, BARE has neither, BIG has a 29-bit ID.
SMALL_DBC = """\
VERSION ""

NS_ :

BS_:

BU_: A B C

BO_ 16 FAST: 8 A
 SG_ V : 0|8@1+ (1,0) [0|255] "" B

BO_ 32 SLOW: 8 B
 SG_ V : 0|8@1+ (1,0) [0|255] "" A

BO_ 48 EVENT: 4 A
 SG_ V : 0|8@1+ (1,0) [0|255] "" B

BO_ 64 BARE: 1 C
 SG_ V : 0|8@1+ (1,0) [0|255] "" A

BO_ 2566848512 BIG: 8 C
 SG_ V : 0|8@1+ (1,0) [0|255] "" A

BA_DEF_ BO_ "GenMsgCycleTime" INT 0 65535;
BA_DEF_ BO_ "GenMsgDelayTime" INT 0 65535;
BA_DEF_ BO_ "GenMsgDeadlineTime" INT 0 65535;
BA_DEF_DEF_ "GenMsgCycleTime" 0;
BA_DEF_DEF_ "GenMsgDelayTime" 0;
BA_DEF_DEF_ "GenMsgDeadlineTime" 0;
BA_ "GenMsgCycleTime" BO_ 16 5;
BA_ "GenMsgCycleTime" BO_ 32 10;
BA_ "GenMsgDeadlineTime" BO_ 32 {deadline_ms};
BA_ "GenMsgDelayTime" BO_ 48 50;
BA_ "GenMsgCycleTime" BO_ 2566848512 25;
"""


def stripped(text: str) -> str:
    return "\n".join(line.rstrip() for line in text.splitlines()) + "\n"


def small_dbc(tmp_path: Path, deadline_ms: int) -> Path:
    path = tmp_path / "small.dbc"
    path.write_text(SMALL_DBC.replace("{deadline_ms}", str(deadline_ms)), encoding="utf-8")
    return path


def test_table_of_odocan_dbc_at_500k(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_cli(capsys, "busload")
    assert (code, err) == (0, "")
    assert stripped(out) == EXPECTED_500K


def test_report(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "busload.json"
    code, _, _ = run_cli(capsys, "busload", "-b", "500000", "--report", str(path))
    report = json.loads(path.read_text())
    assert code == 0
    assert report["schedulable"] is True
    assert report["bitrate"] == 500_000
    assert report["bit_time_us"] == 2.0
    # 17 frames of 135 bits (0.27 ms): 6 at 10 ms (5 sporadic), 4 at 20, 6 at 100 (NAV_STATUS,
    # ODOM_STATUS's summary and page, SIM_TRUTH's three parts: E2EFramesPerCycle), 1 at 1000 ms
    assert report["utilization"] == pytest.approx(0.27 * (6 / 10 + 4 / 20 + 6 / 100 + 1 / 1000))
    assert report["utilization_cyclic"] == pytest.approx(
        0.27 * (1 / 10 + 4 / 20 + 6 / 100 + 1 / 1000))
    # ODOM_AUTH (0x303) is the lowest-priority sporadic message: 12 frames ahead of and with it
    assert (report["worst_slack_message"], report["worst_slack_ms"]) == ("ODOM_AUTH", 6.76)
    wheel = report["messages"][0]
    assert {k: wheel[k] for k in ("name", "id", "bits", "c_ms", "j_ms", "b_ms", "r_ms")} == {
        "name": "WHEEL_ENCODERS", "id": 0x100, "bits": 135,
        "c_ms": 0.27, "j_ms": 0.0, "b_ms": 0.27, "r_ms": 0.54,
    }  # fmt: skip
    # ODOM_STATUS's second frame: one lower frame blocks, 12 other messages' frames and its own
    # first go before it (14 x 0.27 ms), then itself; SIM_TRUTH's third: all 16 other frames
    rows = {m["name"]: m for m in report["messages"]}
    assert [(rows[n]["frames_per_cycle"], rows[n]["b_ms"], rows[n]["r_ms"])
            for n in ("ODOM_STATUS", "SIM_TRUTH")] == [(2, 0.27, 4.05), (3, 0.0, 4.59)]
    ack = next(m for m in report["messages"] if m["name"] == "ODOM_ACK")
    assert ack["kind"] == "sporadic"
    assert "shortest cycle time" in ack["assumption"]
    assert report["sender_tick_ms"]["ODOM_MCU"] == 20.0


def test_what_if_added_message_makes_another_miss(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """At 250 kbit/s a 1.2 ms 8-byte frame at ID 0x050 leaves ODOM_ACK 4.58 ms late."""
    path = tmp_path / "what_if.json"
    argv = ["busload", "-b", "250000", "--add", "HOG:0x050:8:1.2", "--report", str(path)]
    code, out, _ = run_cli(capsys, *argv)
    assert code == 1
    assert out.splitlines()[-1] == "MISS: can miss the deadline: ODOM_ACK, ODOM_AUTH"
    report = json.loads(path.read_text())
    assert report["added"] == ["HOG:0x050:8:1.2"]
    assert report["schedulable"] is False
    first, ack = report["messages"][0], report["messages"][10]
    assert (first["name"], first["r_ms"], first["slack_ms"]) == ("HOG", 1.08, 0.12)
    assert (ack["name"], ack["r_ms"], ack["slack_ms"]) == ("ODOM_ACK", 14.58, -4.58)
    auth = report["messages"][11]  # below ODOM_ACK: at least its own frame later, and late too
    assert auth["name"] == "ODOM_AUTH"
    assert auth["r_ms"] >= ack["r_ms"] + auth["c_ms"]
    assert auth["slack_ms"] == pytest.approx(auth["deadline_ms"] - auth["r_ms"])
    assert auth["slack_ms"] < 0


def test_125k_misses_with_default_sporadic_assumption_and_meets_with_100ms(
    capsys: pytest.CaptureFixture[str],
) -> None:
    code, out, _ = run_cli(capsys, "busload", "-b", "125000")
    assert code == 1
    assert "MISS: can miss the deadline: ODOM_CONFIG, ODOM_ACK, ODOM_AUTH" in out
    code, out, _ = run_cli(capsys, "busload", "-b", "125000", "--sporadic-ms", "100")
    assert code == 0
    assert "least slack 7.840 ms (WHEEL_ENCODERS)" in out


def test_tick_option_sets_the_jitter(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """SIM ticking at 30 ms queues its 100 ms SIM_TRUTH up to 30 - gcd(100, 30) = 20 ms late."""
    path = tmp_path / "tick.json"
    argv = ["busload", "--tick-ms", "SIM=30", "--queue-jitter-ms", "0.5", "--report", str(path)]
    assert run_cli(capsys, *argv)[0] == 0
    messages = {m["name"]: m for m in json.loads(path.read_text())["messages"]}
    assert messages["SIM_TRUTH"]["j_ms"] == 20.5
    assert messages["WHEEL_ENCODERS"]["j_ms"] == 0.5
    assert messages["SIM_TRUTH"]["r_ms"] == pytest.approx(20.5 + 17 * 0.27)  # all 17 frames


def test_another_dbc(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Cycle, deadline and delay attributes read; the message without any is named."""
    report_path = tmp_path / "small.json"
    dbc = small_dbc(tmp_path, deadline_ms=1)
    argv = ["busload", "--dbc", str(dbc), "-b", "125000", "--report", str(report_path)]
    code, out, _ = run_cli(capsys, *argv)
    messages = {m["name"]: m for m in json.loads(report_path.read_text())["messages"]}
    assert code == 1
    assert out.splitlines()[-1] == "MISS: can miss the deadline: SLOW"
    assert "- BARE: no cycle time: sporadic, min inter-arrival = the DBC's shortest cycle" in out
    assert (messages["SLOW"]["period_ms"], messages["SLOW"]["deadline_ms"]) == (10.0, 1.0)
    # blocked by BIG (160 bits, 1.28 ms), then FAST and itself (135 bits, 1.08 ms each)
    assert messages["SLOW"]["r_ms"] == pytest.approx(1.28 + 2 * 1.08)
    assert messages["EVENT"]["period_ms"] == 50.0
    assert "GenMsgDelayTime" in messages["EVENT"][
        "assumption"
    ]
    assert messages["BARE"]["period_ms"] == 5.0  # the shortest cycle, FAST's
    big = messages["BIG"]
    assert big["extended"]
    assert big["bits"] == 160
    assert big["id"] == 0x18FF0000
    assert list(messages)[-1] == "BIG"  # 29-bit ID 0x18FF0000: base 0x63F, the lowest priority
    code, _, _ = run_cli(capsys, "busload", "--dbc", str(small_dbc(tmp_path, 10)), "-b", "125000")
    assert code == 0


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["-b", "123456"], ["--bitrate", "not a CAN bitrate"]),
        (["-b", "fast"], ["--bitrate", "'fast'"]),
        (["-b", "10000"], ["utilization", "> 100 %", "10000 bit/s"]),
        (["-b", "50000"], ["utilization", "> 100 %"]),
        (["--add", "X:1:8"], ["--add", "NAME:ID:DLC:CYCLE_MS"]),
        (["--add", "X:1:8:10:A:B"], ["--add", "NAME:ID:DLC:CYCLE_MS"]),
        (["--add", "X::8:10"], ["--add"]),
        (["--add", "X:zz:8:10"], ["--add", "integers"]),
        (["--add", "X:0x20000000:8:10"], ["--add", "outside"]),
        (["--add", "X:1:9:10"], ["--add", "DLC 9"]),
        (["--add", "X:1:8:0"], ["--add", "positive"]),
        (["--add", "X:1:8:ten"], ["--add", "not a number"]),
        (["--add", "X:0x100:8:10"], ["X", "WHEEL_ENCODERS", "0x100"]),
        (["--add", "SIM_TRUTH:1:8:10"], ["two messages are named SIM_TRUTH"]),
        (["--add", "HOG:1:8:0.3"], ["utilization"]),
        (["--tick-ms", "NOBODY=10"], ["--tick-ms", "NOBODY sends no message"]),
        (["--tick-ms", "SIM"], ["--tick-ms", "NODE=MS"]),
        (["--queue-jitter-ms", "-1"], ["--queue-jitter-ms"]),
        (["--sporadic-ms", "0"], ["--sporadic-ms"]),
        (["--dbc", "/nonexistent/x.dbc"], ["/nonexistent/x.dbc"]),
        (["--report", "/nonexistent/r.json"], ["/nonexistent"]),
    ],
)
def test_bad_input_is_one_line(
    argv: list[str], words: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert_usage_error(capsys, main(["busload", *argv]), *words)


def test_dbc_without_any_cycle_time_needs_sporadic_ms(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "events.dbc"
    path.write_text('VERSION ""\n\nNS_ :\n\nBS_:\n\nBU_: A\n\nBO_ 16 EV: 8 A\n', encoding="utf-8")
    assert_usage_error(capsys, main(["busload", "--dbc", str(path)]), "EV", "--sporadic-ms")
    assert run_cli(capsys, "busload", "--dbc", str(path), "--sporadic-ms", "5")[0] == 0


def test_malformed_dbc_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "broken.dbc"
    path.write_text('VERSION ""\n\nBO_ sixteen FAST: 8 A\n', encoding="utf-8")
    assert_usage_error(capsys, main(["busload", "--dbc", str(path)]), "malformed DBC", str(path))


@pytest.mark.parametrize(("can_id", "says_29_bit"), [("0x7FF", False), ("0x999", True)])
def test_an_added_id_above_0x7ff_is_named_29_bit(
    can_id: str, says_29_bit: bool, capsys: pytest.CaptureFixture[str]
) -> None:
    """0x999 is no 11-bit ID: taken as 29-bit (lower priority, 25 more bits), the output says so
    (an outside trial read the analysis of a typo as that of an 11-bit frame)."""
    code, out, _ = run_cli(capsys, "busload", "--add", f"X:{can_id}:8:10")
    assert code == 0
    assumption = next(line for line in out.splitlines() if line.startswith("- X:"))
    assert ("29-bit ID" in assumption) is says_29_bit
