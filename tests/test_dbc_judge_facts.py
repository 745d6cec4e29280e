"""The judges' bus constants are the DBC's (rule: the DBC is the single source of truth).

Each constant a judge once restated as a literal (a cycle time, a COUNTER lap, a page number, an
APPLY code, a wire width) is checked here against dbc/odocan.dbc read by cantools in the test;
and an edited copy of the DBC (``ODOCAN_DBC``, in a fresh interpreter) shows the judges follow it:
their constants move, and the boot-tick rule of ``host.judge.bootticks`` finds what the edited
DBC's cycles make a power-up tick and nothing where its COUNTERs wrap together within a second.
"""

from __future__ import annotations

import importlib
import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import cantools
import pytest

import odocan
from odocan.firmware.clock import LOST_TIME_PERIODS

ROOT = Path(__file__).resolve().parents[1]
DBC_PATH = ROOT / "dbc" / "odocan.dbc"
TREE = Path(odocan.__file__).resolve().parents[1]


def _db() -> cantools.database.can.Database:
    db = cantools.database.load_file(DBC_PATH, strict=True)
    assert isinstance(db, cantools.database.can.Database)
    return db


def _cycle_ms(name: str) -> int:
    cycle = _db().get_message_by_name(name).cycle_time
    assert cycle
    return int(cycle)


def _frames(name: str) -> int:
    message = _db().get_message_by_name(name)
    assert message.dbc is not None
    attribute = message.dbc.attributes.get("E2EFramesPerCycle")
    return 1 if attribute is None else int(attribute.value)


def _lap(name: str, signal: str = "COUNTER") -> int:
    return int(2 ** _db().get_message_by_name(name).get_signal_by_name(signal).length)


def _bits(name: str, signal: str) -> int:
    return int(_db().get_message_by_name(name).get_signal_by_name(signal).length)


def _choice(name: str, signal: str, value: str) -> int:
    signal_ = _db().get_message_by_name(name).get_signal_by_name(signal)
    choices = {int(raw): str(named) for raw, named in (signal_.choices or {}).items()}
    return next(raw for raw, named in choices.items() if named == value)


def _wire_bits() -> int:
    return _bits("WHEEL_ENCODERS", "LEFT_COUNT")


def _page(value: str) -> int:
    return _choice("ODOM_STATUS", "PAGE", value)


# (module, constant, what the DBC says it is: computed from the DBC by cantools, here)
FACTS = [
    ("odocan.host.judge.bootticks", "POSE_CYCLE_MS", lambda: _cycle_ms("ODOM_POSE_X")),
    ("odocan.host.judge.bootticks", "POSE_FRAMES_PER_CYCLE", lambda: _frames("ODOM_POSE_X")),
    ("odocan.host.judge.bootticks", "POSE_COUNTER_LAP", lambda: _lap("ODOM_POSE_X")),
    ("odocan.host.judge.bootticks", "STATUS_CYCLE_MS", lambda: _cycle_ms("ODOM_STATUS")),
    ("odocan.host.judge.bootticks", "STATUS_FRAMES_PER_CYCLE", lambda: _frames("ODOM_STATUS")),
    ("odocan.host.judge.bootticks", "STATUS_COUNTER_LAP", lambda: _lap("ODOM_STATUS")),
    ("odocan.host.judge.bootticks", "UPTIME_LSB_MS", lambda: round(
        _db().get_message_by_name("ODOM_STATUS").get_signal_by_name("UPTIME").scale * 1000)),
    ("odocan.host.judge.bootticks", "BOOT_WINDOW_MS", lambda: math.gcd(
        _lap("ODOM_POSE_X") * _cycle_ms("ODOM_POSE_X") // _frames("ODOM_POSE_X"),
        _lap("ODOM_STATUS") * _cycle_ms("ODOM_STATUS") // _frames("ODOM_STATUS")) // 2),
    ("odocan.host.judge.sources", "STATUS_CYCLE_MS", lambda: _cycle_ms("ODOM_STATUS")),
    ("odocan.host.judge.sources", "STATUS_COUNTER_MODULO", lambda: _lap("ODOM_STATUS")),
    ("odocan.host.judge.livewindow", "CYCLE_S", lambda: _cycle_ms("WHEEL_ENCODERS") / 1000),
    ("odocan.host.judge.livedistance", "CYCLE_S", lambda: _cycle_ms("WHEEL_ENCODERS") / 1000),
    ("odocan.host.judge.livetwist", "CYCLE_S", lambda: _cycle_ms("WHEEL_ENCODERS") / 1000),
    ("odocan.host.judge.compare", "TWIST_SILENCE_S",
     lambda: (LOST_TIME_PERIODS - 0.5) * _cycle_ms("WHEEL_ENCODERS") / 1000),
    # the encoder period and its periods per second (CTRL_UPTIME's second), once the firmware's
    *[(f"odocan.host.judge.{m}", "ENCODER_PERIOD_US", lambda: _cycle_ms("WHEEL_ENCODERS") * 1000)
      for m in ("reference", "twins", "distance", "gapbound")],
    *[(f"odocan.host.judge.{m}", "PERIODS_PER_S", lambda: 1000 // _cycle_ms("WHEEL_ENCODERS"))
      for m in ("ctrlrestart", "livepose")],
    ("odocan.host.judge.samples", "WIRE_COUNTER_BITS", _wire_bits),
    ("odocan.host.judge.livepose", "WIRE_BITS", _wire_bits),
    ("odocan.host.experiments.drive", "WIRE_COUNTER_BITS", _wire_bits),
    ("odocan.host.judge.samples", "ENC_E2E_PAGE", lambda: _page("E2E_WHEEL_ENCODERS")),
    ("odocan.host.judge.gapseen", "LOST_PAGE", lambda: _page("E2E_WHEEL_ENCODERS")),
    ("odocan.host.judge.losses", "LOST_PAGE", lambda: _page("E2E_WHEEL_ENCODERS")),
    ("odocan.host.judge.gapseen", "TOTALS_PAGE", lambda: _page("FRAME_TOTALS")),
    ("odocan.host.judge.reboots", "SUMMARY_PAGE", lambda: _page("SUMMARY")),
    ("odocan.host.judge.statuslatch", "SUMMARY_PAGE", lambda: _page("SUMMARY")),
    ("odocan.host.judge.stream_facts", "SUMMARY_PAGE", lambda: _page("SUMMARY")),
    ("odocan.host.judge.nearthreshold", "SUMMARY_PAGE", lambda: _page("SUMMARY")),
    ("odocan.host.judge.profilepage", "PROFILE_PAGE", lambda: _page("PROFILE")),
    ("odocan.host.judge.setposes", "APPLY_FIELD",
     lambda: _choice("ODOM_SET_POSE", "FIELD", "APPLY")),
    ("odocan.host.judge.configs", "APPLY_PARAM", lambda: _choice("ODOM_CONFIG", "PARAM", "APPLY")),
    ("odocan.host.protocol.session", "FRESHNESS_WAIT_S",
     lambda: 1.5 * _cycle_ms("ODOM_FRESHNESS") / 1000),
    # the E2E COUNTER's lap (one for every message: dbcfacts.e2e_counter_lap) and its masks
    ("odocan.host.protocol.e2e", "COUNTER_MASK", lambda: _lap("WHEEL_ENCODERS") - 1),
    ("odocan.host.protocol.e2e", "MAX_DELTA_COUNTER", lambda: _lap("WHEEL_ENCODERS") - 1),
    ("odocan.host.protocol.e2e_retract", "COUNTER_MASK", lambda: _lap("WHEEL_ENCODERS") - 1),
    ("odocan.host.protocol.e2e_retract", "MAX_WINDOW", lambda: _lap("WHEEL_ENCODERS") - 1),
    ("odocan.host.protocol.e2e_cycles", "COUNTER_CYCLE", lambda: _lap("WHEEL_ENCODERS")),
    ("odocan.host.protocol.e2e_periods", "COUNTER_MODULO", lambda: _lap("WHEEL_ENCODERS")),
    ("odocan.host.protocol.pose", "COUNTER_VALUES", lambda: _lap("ODOM_POSE_X", "ENC_COUNTER")),
    ("odocan.host.judge.step_periods", "COUNTER_VALUES", lambda: _lap("WHEEL_ENCODERS")),
    ("odocan.host.judge.gapfill", "COUNTER_MODULO", lambda: _lap("WHEEL_ENCODERS")),
    ("odocan.host.judge.resendalias", "COUNTER_MODULO", lambda: _lap("WHEEL_ENCODERS")),
    ("odocan.host.judge.senderseq", "LAP", lambda: _lap("WHEEL_ENCODERS")),
    ("odocan.host.judge.liveplace", "LAP", lambda: _lap("WHEEL_ENCODERS")),
    ("odocan.host.judge.holepages", "LAP", lambda: _lap("WHEEL_ENCODERS")),
    ("odocan.host.judge.livelaphold", "LAP", lambda: _lap("WHEEL_ENCODERS")),
    ("odocan.host.judge.holechain", "LAP_PERIODS", lambda: _lap("WHEEL_ENCODERS")),
    ("odocan.host.judge.livepose", "RING", lambda: _lap("WHEEL_ENCODERS")),
    ("odocan.host.judge.liveholdstep", "COUNTER_MODULO", lambda: _lap("WHEEL_ENCODERS")),
    ("odocan.host.mqtt.haltpath", "COUNTER_MASK", lambda: _lap("WHEEL_ENCODERS") - 1),
]


@pytest.mark.parametrize(("module", "name", "expected"), FACTS,
                         ids=[f"{m.rsplit('.', 1)[1]}.{n}" for m, n, _ in FACTS])
def test_judge_constant_is_the_dbcs(module: str, name: str, expected: object) -> None:
    assert callable(expected)
    assert getattr(importlib.import_module(module), name) == expected()


PROBE = """
import json
import math
from odocan.host.judge import bootticks, ctrlrestart, livedistance, livetwist, livewindow, sources
from odocan.host.judge import reference
tick_s = bootticks.POSE_CYCLE_MS / 1000
print(json.dumps({
    "enc_period_us": reference.ENCODER_PERIOD_US,
    "periods_per_s": ctrlrestart.PERIODS_PER_S,
    "pose_cycle_ms": bootticks.POSE_CYCLE_MS,
    "status_cycle_ms": sources.STATUS_CYCLE_MS,
    "enc_cycle_s": [livewindow.CYCLE_S, livedistance.CYCLE_S, livetwist.CYCLE_S],
    # a summary of UPTIME 0, COUNTER 0, 0.6 of a pose cycle after an ODOM_POSE_X of COUNTER 0
    "late_boot": bootticks.boot_tick(0, 0, 10.0 + 0.6 * tick_s, (10.0, 0, True), None, None),
    # held back 3.5 pose cycles, behind the poses of COUNTER 1, 2, 3 counting on from it
    "held_boot": bootticks.boot_tick(0, 0, 10.0 + 3.5 * tick_s, (10.0, 3, True), None, None),
    # 8 pose cycles after it (one life at 0.8 s, the DBC as it is): no boot tick
    "phase_step": bootticks.boot_tick(0, 0, 10.0 + 8 * tick_s, (10.0, 8, True), None, None),
    # the same 0.3 of a cycle after: the power-up tick's signature
    "boot": bootticks.boot_tick(0, 0, 10.0 + 0.3 * tick_s, (10.0, 0, True), None, None),
    "boot_10ms": bootticks.boot_tick(0, 0, 10.015, (10.0, 0, True), None, None),
}))
"""


def _edited(tmp_path: Path, cycles_ms: dict[int, int]) -> Path:
    """A copy of the DBC with the GenMsgCycleTime of the frame ids in ``cycles_ms`` changed."""
    text = DBC_PATH.read_text(encoding="utf-8")
    for frame_id, cycle in cycles_ms.items():
        text, n = re.subn(rf'BA_ "GenMsgCycleTime" BO_ {frame_id} \d+;',
                          f'BA_ "GenMsgCycleTime" BO_ {frame_id} {cycle};', text)
        assert n == 1
    path = tmp_path / f"edited-{'-'.join(map(str, cycles_ms.values()))}.dbc"
    path.write_text(text, encoding="utf-8")
    return path


def _probe(tmp_path: Path, dbc: Path) -> dict[str, object]:
    env = {**os.environ, "ODOCAN_DBC": str(dbc), "ODOCAN_CACHE_DIR": str(tmp_path / "cache"),
           "PYTHONPATH": str(TREE)}
    done = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True,
                          text=True, check=False, timeout=120)
    assert done.returncode == 0, done.stderr
    result: dict[str, object] = json.loads(done.stdout)
    return result


def test_judges_follow_an_edited_dbc(tmp_path: Path) -> None:
    as_is = _probe(tmp_path, DBC_PATH)
    assert as_is["pose_cycle_ms"] == 20
    assert as_is["status_cycle_ms"] == 100
    assert as_is["enc_cycle_s"] == [0.01] * 3
    assert (as_is["enc_period_us"], as_is["periods_per_s"]) == (10_000, 100)
    assert (as_is["boot"], as_is["late_boot"], as_is["boot_10ms"]) == (True, True, True)
    assert (as_is["held_boot"], as_is["phase_step"]) == (True, False)
    # WHEEL_ENCODERS at 20 ms, ODOM_POSE_X at 40 ms, ODOM_STATUS at 200 ms: COUNTERs wrap
    # together every lcm(640, 1600) = 3.2 s, still more than UPTIME's second
    slow = _probe(tmp_path, _edited(tmp_path, {256: 20, 512: 40, 896: 200}))
    assert slow["pose_cycle_ms"] == 40
    assert slow["status_cycle_ms"] == 200
    assert slow["enc_cycle_s"] == [0.02] * 3
    assert (slow["enc_period_us"], slow["periods_per_s"]) == (20_000, 50)
    # the phase step is gcd(640, 1600) = 320 ms: a boot summary told up to 160 ms (4 poses) on
    assert (slow["boot"], slow["late_boot"], slow["boot_10ms"]) == (True, True, True)
    assert (slow["held_boot"], slow["phase_step"]) == (True, False)


def test_no_boot_tick_where_the_counters_wrap_within_a_second(tmp_path: Path) -> None:
    # ODOM_POSE_X at 5 ms: its COUNTER wraps every 80 ms, with ODOM_STATUS's every 800 ms:
    # both read 0 together every 0.8 s, within UPTIME 0, so the signature proves no reboot
    fast = _probe(tmp_path, _edited(tmp_path, {512: 5}))
    assert fast["pose_cycle_ms"] == 5
    assert (fast["boot"], fast["late_boot"], fast["boot_10ms"]) == (False, False, False)
    assert (fast["held_boot"], fast["phase_step"]) == (False, False)


# Every constant of a COUNTER lap, and what it is of the lap (``LAP_PROBE`` prints them)
LAP_CONSTANTS = {
    "e2e.COUNTER_LAP": 0, "e2e.COUNTER_MASK": -1, "e2e.MAX_DELTA_COUNTER": -1,
    "e2e_retract.COUNTER_MASK": -1, "e2e_retract.MAX_WINDOW": -1,
    "e2e_retract.SEARCH_FRAMES": 0, "e2e_cycles.COUNTER_CYCLE": 0,
    "e2e_periods.COUNTER_MODULO": 0, "pose.COUNTER_VALUES": 0, "step_periods.COUNTER_VALUES": 0,
    "gapfill.COUNTER_MODULO": 0, "resendalias.COUNTER_MODULO": 0, "senderseq.LAP": 0,
    "liveplace.LAP": 0, "liveplace.MASK": -1, "holepages.LAP": 0, "livelaphold.LAP": 0,
    "holechain.LAP_PERIODS": 0, "livepose.RING": 0, "livepose.RING_MASK": -1,
    "liveholdstep.COUNTER_MODULO": 0, "haltpath.COUNTER_MASK": -1,
}
HALF_LAPS = ("livewindow.HALF_LAP", "samples.HALF_LAP")  # a COUNTER step read as -lap/2..

LAP_PROBE = """
import json
import sys
import numpy as np
from odocan.host.judge import gapfill, holechain, holepages, liveholdstep, livelaphold, liveplace
from odocan.host.judge import livepose, livewindow, resendalias, samples, senderseq, step_periods
from odocan.host.mqtt import haltpath
from odocan.host.protocol import e2e, e2e_cycles, e2e_periods, e2e_retract, pose
from odocan.host.protocol.dbcplan import default_plan
names = sys.argv[1:]
found = {name: getattr(globals()[name.split(".")[0]], name.split(".")[1], None) for name in names}
found["data_ids"] = len(e2e.e2e_messages(default_plan())[0x100].data_ids or ())
# the sender's numbering of a COUNTER at the lap's last value then 0 a period on (one period),
# and of a COUNTER that reads the same a lap of periods on (a lap lost)
last, cycle_s = e2e.COUNTER_MASK, 0.01
seqs = [senderseq.sender_seq(np.array(counters), np.array(times) * cycle_s, cycle_s)
        for counters, times in (([last, 0], [0, 1]), ([last, last], [0, last + 1]))]
found["wrap_step"], found["lap_step"] = (int(seq[-1]) for seq in seqs)
print(json.dumps(found))
"""


def _counter_bits(tmp_path: Path, bits: int) -> Path:
    """A copy of the DBC whose every COUNTER (and the ENC_COUNTER/REQUEST_COUNTER echoing one)
    has ``bits`` bits, each E2EDataIDs list cut to its first 2 ** ``bits`` data IDs."""
    text = DBC_PATH.read_text(encoding="utf-8")
    text, n = re.subn(r"COUNTER : (\d+)\|4@1\+ \(1,0\) \[0\|15\]",
                      rf"COUNTER : \1|{bits}@1+ (1,0) [0|{(1 << bits) - 1}]", text)
    assert n > 10
    text, n = re.subn(r'(BA_ "E2EDataIDs" BO_ \d+ ")([\d,]+)"',
                      lambda m: m[1] + ",".join(m[2].split(",")[: 1 << bits]) + '"', text)
    assert n > 10
    path = tmp_path / f"counter{bits}.dbc"
    path.write_text(text, encoding="utf-8")
    return path


def _lap_probe(tmp_path: Path, dbc: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "ODOCAN_DBC": str(dbc), "ODOCAN_CACHE_DIR": str(tmp_path / "cache"),
           "PYTHONPATH": str(TREE)}
    return subprocess.run([sys.executable, "-c", LAP_PROBE, *LAP_CONSTANTS, *HALF_LAPS], env=env,
                          capture_output=True, text=True, check=False, timeout=120)


def test_counter_laps_follow_an_edited_dbc(tmp_path: Path) -> None:
    for dbc, lap in ((DBC_PATH, 16), (_counter_bits(tmp_path, 3), 8)):
        done = _lap_probe(tmp_path, dbc)
        assert done.returncode == 0, done.stderr
        found = json.loads(done.stdout)
        assert {name: found[name] for name in (*LAP_CONSTANTS, *HALF_LAPS)} == {
            **{name: lap + less for name, less in LAP_CONSTANTS.items()},
            **dict.fromkeys(HALF_LAPS, lap // 2)}, dbc.name
        assert (found["data_ids"], found["wrap_step"], found["lap_step"]) == (lap, 1, lap)


def test_a_dbc_whose_counters_differ_is_refused_by_name(tmp_path: Path) -> None:
    # MOTOR_CMD's COUNTER widened to 8 bits (bits 12..15 are free): past Profile 2's 16 values
    text = DBC_PATH.read_text(encoding="utf-8")
    edited, n = re.subn(r"(BO_ 272 MOTOR_CMD: 8 ODOM_MCU\n SG_ CHECKSUM [^\n]*\n"
                        r" SG_ COUNTER : 8\|)4@1\+ \(1,0\) \[0\|15\]",
                        r"\g<1>8@1+ (1,0) [0|255]", text)
    assert n == 1
    dbc = tmp_path / "motor-cmd-counter8.dbc"
    dbc.write_text(edited, encoding="utf-8")
    done = _lap_probe(tmp_path, dbc)
    assert done.returncode != 0
    assert "MOTOR_CMD COUNTER values 256: E2E Profile 2 counts at most 16" in done.stderr


def test_a_counter_past_profile_2_is_refused() -> None:
    from odocan.host.protocol.dbcfacts import DbcFactError, e2e_counter_lap

    db = cantools.database.load_string(
        'VERSION ""\nBS_:\nBU_: A\nBO_ 256 WHEEL_ENCODERS: 8 A\n'
        ' SG_ COUNTER : 8|5@1+ (1,0) [0|31] "-" A\n', strict=True)
    assert isinstance(db, cantools.database.can.Database)
    with pytest.raises(DbcFactError, match="WHEEL_ENCODERS COUNTER values 32: E2E Profile 2"):
        e2e_counter_lap(db)
