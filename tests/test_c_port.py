"""The C port (firmware/c): bit-exact against the golden vectors, natively and on 32-bit ARM.

``make -C firmware/c check`` builds the port natively with UBSan + ASan and as a static 32-bit ARM
Linux binary run under qemu-arm, and replays over 10^6 steps of vectors (both shipped robot
profiles, the three integrators, counter wraps; plus a 32-bit-counter corner that saturates) from
the JSON and the CSV files. The tests skip with the reason
when a tool is missing, except under ``CI=true``, where a missing tool is a failure.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import os
import random
import re
import shutil
import subprocess
import sys
from collections.abc import Callable
from functools import partial
from pathlib import Path

import pytest

from odocan.firmware import cmac, config, e2e, fixmath, frames, nav, odometry, secoc, trig
from odocan.firmware.ecu import OdomEcu
from odocan.firmware.errors import ErrorFlag, ErrorMask, Reason, State
from odocan.firmware.fixmath import (
    I16_MAX,
    I16_MIN,
    I32_MAX,
    I32_MIN,
    I64_MAX,
    I64_MIN,
    U32_MAX,
    U64_MAX,
    wrap_signed,
)
from odocan.firmware.frames import NavGoal, NavGoalField, NavState
from odocan.host.cli.app import main
from odocan.host.judge import vectors
from odocan.sim import frames as sf
from odocan.sim.rig import firmware_params
from odocan.sim.robot import load
from tests import host_frames as hf
from tools import gen_trig_tables

ROOT = Path(__file__).resolve().parent.parent
C_DIR = ROOT / "firmware" / "c"
CROSS_PACKAGES = "gcc-arm-linux-gnueabihf libc6-dev-armhf-cross qemu-user"


def _require(*tools: str) -> None:
    """Skip (fail under CI=true) unless every tool is on PATH."""
    missing = [tool for tool in tools if shutil.which(tool) is None]
    if not missing:
        return
    reason = f"the C port needs {', '.join(missing)} (apt-get install gcc make {CROSS_PACKAGES})"
    if os.environ.get("CI") == "true":
        pytest.fail(f"CI=true: {reason}")
    pytest.skip(reason)


def _make(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        ["make", "--no-print-directory", "-C", str(C_DIR), f"PYTHON={sys.executable}", *args],
        capture_output=True,
        text=True,
        check=False,
    )


def test_the_c_trig_tables_are_generated_from_the_same_values() -> None:
    assert gen_trig_tables.render_c() == gen_trig_tables.TARGET_C.read_text(encoding="utf-8")
    values = gen_trig_tables.compute()
    header = gen_trig_tables.TARGET_C.read_text(encoding="utf-8")
    sin_q62 = values["SIN_Q62"]
    assert isinstance(sin_q62, list)
    assert f"INT64_C(0x{sin_q62[256]:X})" in header  # sin(pi/2) = 2^62, the last knot
    assert f"#define SIN_K3 UINT64_C(0x{values['SIN_K3']:X})" in header


def test_the_c_frame_code_is_what_cantools_generates_from_the_dbc(tmp_path: Path) -> None:
    _require("make", "awk", "sed", "diff")
    result = _make("dbc-check", f"BUILD={tmp_path}")
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-2000:]
    for name in ("odocan.c", "odocan.h"):
        committed = (C_DIR / "dbc" / name).read_text(encoding="utf-8")
        assert "float" not in committed
        assert "double" not in committed
        assert "odocan_nav_goal_unpack" in committed


def test_dbc_check_catches_a_stale_frame_file(tmp_path: Path) -> None:
    _require("make", "awk", "sed", "diff")
    stale = tmp_path / "c"
    shutil.copytree(C_DIR, stale, ignore=shutil.ignore_patterns("build"))
    header = stale / "dbc" / "odocan.h"
    header.write_text(header.read_text().replace("(0x100u)", "(0x101u)", 1))
    argv = ["make", "--no-print-directory", "-C", str(stale), f"PYTHON={sys.executable}"]
    result = subprocess.run(
        [*argv, f"REPO={ROOT}", "dbc-check", f"BUILD={tmp_path / 'b'}"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode != 0
    assert "0x101u" in result.stdout


@pytest.mark.slow
def test_make_check_is_bit_exact_natively_and_on_arm32(tmp_path: Path) -> None:
    _require("make", "gcc", "arm-linux-gnueabihf-gcc", "qemu-arm")
    result = _make("check", f"BUILD={tmp_path / 'build'}", f"VECTORS={tmp_path / 'vectors'}")
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    for target in ("native", "arm32"):
        lines = re.findall(
            rf"^{target} (\w+): vectors_check: (\d+) steps from JSON, (\d+) from CSV, "
            r"(\d+) mismatches$",
            result.stdout,
            re.MULTILINE,
        )
        robots = ("pmir", "kobuki", "extreme32")
        sets = {name for name, *_ in lines}
        assert sets == {f"{r}_{i}" for r in robots for i in ("euler", "rk2", "exact")}
        assert all(json == csv and mismatches == "0" for _, json, csv, mismatches in lines)
        shipped = [int(csv) for name, _, csv, _ in lines if not name.startswith("extreme32")]
        assert sum(shipped) >= 1_000_000


def test_one_changed_integer_fails_the_c_check(tmp_path: Path) -> None:
    _require("make", "gcc")
    build = tmp_path / "build"
    assert _make(f"BUILD={build}", f"{build}/vectors_check").returncode == 0
    out = tmp_path / "v"
    argv = [sys.executable, "-m", "odocan", "vectors", "--duration", "1", "--out", str(out)]
    argv += ["--random-steps", "300", "--integrator", "rk2"]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    subprocess.run(argv, check=True, capture_output=True, env=env)
    checker = [str(build / "vectors_check"), str(out / "vectors.json")]
    good = subprocess.run([*checker, str(out / "random_steps_0.csv")], capture_output=True)
    assert good.returncode == 0, good.stderr

    lines = (out / "random_steps_0.csv").read_text().splitlines()
    fields = lines[150].split(",")
    fields[5] = str(int(fields[5]) ^ 1)  # heading_bam64 of step 149, its lowest bit
    lines[150] = ",".join(fields)
    bad_csv = tmp_path / "bad.csv"
    bad_csv.write_text("\n".join(lines) + "\n")
    bad = subprocess.run([*checker, str(bad_csv)], capture_output=True, text=True)
    assert bad.returncode == 1
    assert "step 149: heading_bam64" in bad.stderr

    text = (out / "vectors.json").read_text()
    x = re.findall(r'"x_q40_m": (-?\d+)', text)[200]
    bad_json = tmp_path / "bad.json"
    bad_json.write_text(text.replace(f'"x_q40_m": {x},', f'"x_q40_m": {int(x) + 1},', 1))
    bad = subprocess.run(
        [str(build / "vectors_check"), str(bad_json)], capture_output=True, text=True
    )
    assert bad.returncode == 1

    wrong_radius = text.replace(
        '"wheel_radius_left_nm": 75000000', '"wheel_radius_left_nm": 75000001'
    )
    bad_json.write_text(wrong_radius)
    bad = subprocess.run(
        [str(build / "vectors_check"), str(bad_json)], capture_output=True, text=True
    )
    assert bad.returncode == 1
    assert "derive_constants differs" in bad.stderr


def test_the_long_random_case_wraps_spins_and_is_deterministic() -> None:
    case = vectors.random_case(16, 3000, seed=4)
    assert case.counts == vectors.random_case(16, 3000, seed=4).counts
    assert len(case.counts) == 3001
    assert all(0 <= c < 1 << 16 for pair in case.counts for c in pair)
    deltas = [
        (wrap_signed(b[0] - a[0], 16), wrap_signed(b[1] - a[1], 16))
        for a, b in itertools.pairwise(case.counts)
    ]
    pairs = list(itertools.pairwise(case.counts))
    assert any(b[0] < a[0] and dl > 0 for (a, b), (dl, _) in zip(pairs, deltas, strict=True))
    assert any(dl == -dr != 0 for dl, dr in deltas), "a spin in place"
    assert any(dl == dr != 0 for dl, dr in deltas), "a straight step"
    assert max(abs(d) for pair in deltas for d in pair) > 10_000, "an extreme step"


def test_random_steps_option(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "v"
    assert main(["vectors", "--duration", "0.5", "--random-steps", "50", "--out", str(out)]) == 0
    assert len(vectors.read_csv(out / "random_steps_0.csv")) == 51
    assert main(["vectors", "--random-steps", "-1", "--out", str(out)]) == 2
    assert capsys.readouterr().err.startswith("error: argument --random-steps: must be in [0, ")


# CRC8H2F test values of the AUTOSAR SWS CRC Library (an independent reference for both sides).
AUTOSAR_CRC8H2F = {
    "00000000": 0x12,
    "F20183": 0xC2,
    "0FAA0055": 0xC6,
    "00FF5511": 0x77,
    "332255AABBCCDDEEFF": 0x11,
    "926B55": 0x33,
    "FFFFFFFF": 0x6C,
    "313233343536373839": 0xDF,  # "123456789": the check value
}


def _probe_script(seed: int) -> tuple[list[str], list[str]]:
    """Probe commands and the Python firmware's answers (see firmware/c/probe.c)."""
    rng = random.Random(seed)
    cmds: list[str] = []
    want: list[str] = []

    def ask(cmd: str, *answer: object) -> None:
        cmds.append(cmd)
        want.append(" ".join(str(a) for a in answer))

    _trig_probes(rng, ask)
    _fixmath_probes(rng, ask)
    _config_probes(rng, ask)
    _crc_probes(rng, ask)
    for _ in range(40):
        _e2e_session(rng, ask)
    _nav_functions(rng, ask)
    for _ in range(12):
        _nav_session(rng, ask)
    _frames(rng, ask)
    for robot, integrator, timed in (
        ("pmir", "exact", True),
        ("kobuki", "rk2", True),
        ("pmir", "euler", False),
    ):
        _ecu_session(rng, ask, robot, integrator, timed=timed)
    _ecu_session(rng, ask, "kobuki", "exact", counts_per_rev=0)  # FAULT until configured
    _ecu_session(rng, ask, "kobuki", "euler", counter_bits=32)  # rebuilt from the 24-bit wire
    _secoc_functions(rng, ask)
    _secured_ecu_session(rng, ask)
    _secured_ecu_session(rng, ask, key=b"")  # no valid key: fails closed
    _secured_ecu_session(rng, ask, nvm_fails=True)  # the EPOCH cell refuses writes
    return cmds, want


def _trig_probes(rng: random.Random, ask: Callable[..., None]) -> None:
    """sin/cos, atan2 and the chord factor on their knots, branch edges and random inputs."""
    angles = [(q << 30) + (k << 22) + o for q in range(4) for k in range(257) for o in (-3, 0, 3)]
    angles += [(1 << 21) * k + t for k in range(2048) for t in (-1, 0, 1)]  # knot ties
    angles += [rng.getrandbits(32) for _ in range(20_000)]
    for a in angles:
        ask(f"sincos {a & U32_MAX}", *trig.sincos_q30(a & U32_MAX))
    specials = [0, 1, -1, I64_MIN, I64_MAX, 1 << 46, (1 << 47) - 1]
    for _ in range(6_000):
        bits = rng.randrange(1, 64)
        y, x = (rng.randrange(-(1 << bits), 1 << bits) for _ in range(2))
        ask(f"atan2 {y} {x}", trig.atan2_bam32(y, x))
    for y, x in itertools.product(specials + [-s for s in specials[1:]], repeat=2):
        ask(f"atan2 {y} {x}", trig.atan2_bam32(y, x))
    limits = [1 << 39, 1 << 57]  # the chord factor's branch edges, as u_q60
    dheads = [rng.randrange(I64_MIN, I64_MAX + 1) for _ in range(3_000)]
    dheads += [rng.randrange(-(1 << 45), 1 << 45) for _ in range(1_000)]
    dheads += [I64_MIN, I64_MAX, 0, 1, -1]
    dheads += [((lim << 65) // config.TWO_PI_Q60) + d for lim in limits for d in range(-3, 4)]
    for dh in dheads:
        ask(f"chord {dh}", odometry.chord_factor_q62(dh))


def _fixmath_probes(rng: random.Random, ask: Callable[..., None]) -> None:
    """The fixmath helpers on random operands of every width and on their extremes."""
    for _ in range(3_000):
        a, b, c = (rng.getrandbits(rng.randrange(1, 65)) for _ in range(3))
        errors = ErrorMask()
        ask(f"muldiv {a} {b} {c}", fixmath.muldiv_round_u64(a, b, c, errors), errors.bits)
    for _ in range(3_000):
        a, b = (rng.randrange(I64_MIN, I64_MAX + 1) >> rng.randrange(64) for _ in range(2))
        shift = rng.randrange(1, 128)
        errors = ErrorMask()
        ask(f"mulshr {a} {b} {shift}", fixmath.mul_shr_round_i64(a, b, shift, errors), errors.bits)
    for num, den in _div_q62_operands(rng):
        ask(f"div_q62 {num} {den >> 64} {den & U64_MAX}", fixmath.div_q62_i128(num, den >> 64,
                                                                       den & U64_MAX))
    for v in [rng.randrange(I64_MIN, I64_MAX + 1) for _ in range(2_000)] + [I64_MIN, I64_MAX]:
        d = rng.choice([1, 2, 3, 10, rng.randrange(1, I64_MAX)])
        ask(f"div_round {v} {d}", fixmath.div_round_i64(v, d))
    for n in [rng.getrandbits(rng.randrange(1, 65)) for _ in range(2_000)] + [0, 1, 2, U64_MAX]:
        ask(f"isqrt {n}", fixmath.isqrt_u64(n))
    for _ in range(2_000):
        v, bits = rng.getrandbits(32), rng.choice((16, 32))
        ask(f"wrap_signed {v} {bits}", fixmath.wrap_signed(v, bits))


def _div_q62_operands(rng: random.Random) -> list[tuple[int, int]]:
    """(num, den) in div_q62_i128's domain: 2^63 <= |den| < 2^126, |num| <= |den|, num an i64;
    the steps' own (den = dtheta_w + n 2^64) and the edges of the normalization."""
    pairs = [(I64_MIN, 1 << 63), (I64_MIN, -(1 << 63)), (I64_MAX, 1 << 63), (0, 1 << 64),
             (1 << 62, (1 << 64) - 1), (-1, (1 << 126) - 1), (I64_MAX, -(1 << 125))]
    for _ in range(3_000):
        wrapped = rng.randrange(I64_MIN, I64_MAX + 1)
        turns = rng.choice([1, -1, 2, -3, rng.randrange(-(1 << 29), 1 << 29) or 5])
        pairs.append((wrapped, wrapped + (turns << 64)))
    for _ in range(1_000):
        den = rng.choice([1, -1]) * rng.randrange(1 << 63, 1 << rng.randrange(64, 127))
        pairs.append((rng.randrange(-min(abs(den), 1 << 63), min(abs(den), I64_MAX + 1)), den))
    return pairs


def _config_probes(rng: random.Random, ask: Callable[..., None]) -> None:
    """validate and derive_constants on random parameters, mostly in range."""
    for _ in range(1_500):
        counts_per_rev = rng.randrange(0, 1 << 25)
        left_nm, right_nm = (rng.randrange(0, 2_100_000_000) for _ in range(2))
        params = config.RobotParams(
            counts_per_rev,
            left_nm,
            right_nm,
            rng.randrange(0, U32_MAX),
            rng.choice((16, 32, 8)),
            rng.choice((0, 1, 2, 3)),
            rng.choice((0, 1, 700, 4_000, 65_535, 65_536, rng.randrange(0, 1 << 32))),
        )
        if rng.random() < 0.7:  # mostly in range, so that the constants are derived
            params = dataclasses.replace(
                params,
                counts_per_rev=rng.randrange(1, 1 << 24),
                wheel_radius_left_nm=rng.randrange(1_000_000, 2_000_000_001),
                wheel_radius_right_nm=rng.randrange(1_000_000, 2_000_000_001),
                wheelbase_nm=rng.randrange(10_000_000, 4_000_000_001),
                counter_bits=rng.choice((16, 32)),
                integrator=rng.choice((0, 1, 2)),
                max_wheel_speed_mm_s=rng.randrange(1, 65_536),
            )
        speed_mm_s = rng.choice((4_000, 500, 65_535, rng.randrange(1, 65_536)))
        ask(f"config_speed {speed_mm_s} " + " ".join(str(v) for v in dataclasses.astuple(params)),
            int(config.validate_at_speed(params, speed_mm_s)))
        cmd = "config " + " ".join(str(v) for v in dataclasses.astuple(params))
        reason = config.validate(params)
        if reason != config.ConfigReason.OK:
            ask(cmd, int(reason))
            continue
        errors = ErrorMask()
        k = config.derive_constants(params, errors)
        ask(
            cmd,
            0,
            k.m_per_count_left_q48_m,
            k.m_per_count_right_q48_m,
            k.bam64_per_count_left,
            k.bam64_per_count_right,
            errors.bits,
        )


def _crc_probes(rng: random.Random, ask: Callable[..., None]) -> None:
    """The Profile 2 CRC on AUTOSAR's vectors and random data, and its table."""
    for hex_bytes, crc in AUTOSAR_CRC8H2F.items():
        assert e2e.crc8h2f(bytes.fromhex(hex_bytes)) == crc
        ask(f"crc {hex_bytes}", crc)
    for _ in range(500):
        data = rng.randbytes(rng.randrange(1, 40))
        ask(f"crc {data.hex()}", e2e.crc8h2f(data))
    ask("table", *e2e.CRC8H2F_TABLE)


SECOC_KEY = bytes.fromhex("2b7e151628aed2a6abf7158809cf4f3c")  # RFC 4493's


def _secoc_functions(rng: random.Random, ask: Callable[..., None]) -> None:
    """AES-CMAC on every tail length (RFC 4493's key and random ones) and the authenticator."""
    for length in (0, 1, 15, 16, 17, 31, 32, 33, 40, 63, 64):
        for key in (SECOC_KEY, rng.randbytes(16)):
            msg = rng.randbytes(length)
            tag = cmac.cmac(cmac.cmac_key(key), msg)
            ask(f"cmac {key.hex()} {msg.hex() or '-'}", tag.hex().upper())
    for _ in range(300):
        key, pdu = rng.randbytes(16), rng.randbytes(8)
        can_id = rng.choice(secoc.SECURED_IDS)
        fv = rng.getrandbits(48)
        mac = secoc.authenticator(cmac.cmac_key(key), can_id, pdu, fv)
        ask(f"auth {key.hex()} {can_id} {pdu.hex()} {fv}", mac)


class _Cell:
    """The EPOCH cell of the Python ECU in the secured sessions (the probe has its own)."""

    def __init__(self, fails: bool) -> None:
        self.epoch = 0
        self.fails = fails

    def read_epoch(self) -> int:
        return self.epoch

    def write_epoch(self, epoch: int) -> bool:
        if not self.fails:
            self.epoch = epoch
        return not self.fails


def _secured_ecu_session(
    rng: random.Random, ask: Callable[..., None], key: bytes = SECOC_KEY, nvm_fails: bool = False
) -> None:
    """A provisioned ECU, frame for frame: genuine, forged, stale, replayed (also after a
    reboot), unsigned, displaced and orphan commands on all three secured messages."""
    _SecuredSession(rng, ask, key, nvm_fails).run(400)


class _SecuredSession:
    """The state of one ``_secured_ecu_session``: the Python ECU and the C one fed the same
    frames, the host's counters and freshness, and the recorded genuine commands."""

    def __init__(
        self, rng: random.Random, ask: Callable[..., None], key: bytes, nvm_fails: bool
    ) -> None:
        self.rng, self.ask, self.key = rng, ask, key
        self.params = firmware_params(load("pmir"), "exact")
        self.cell = _Cell(nvm_fails)
        self.tx = _RecordingTx()
        self.mac_key = cmac.cmac_key(SECOC_KEY)
        ask(f"nvm 0 {int(nvm_fails)}", "ok")
        self.ecu = self.boot()
        self.counters: dict[int, int] = {}
        self.host_fv = 0
        self.recorded: list[list[tuple[int, bytes]]] = []
        self.count = 0

    def boot(self) -> OdomEcu:
        self.ask(f"ecu_new {' '.join(str(v) for v in dataclasses.astuple(self.params))}", "ok")
        self.ask(f"ecu_secoc {self.key.hex() or '-'}", "ok")
        return OdomEcu(self.tx, self.params, secoc_key=self.key, nvm=self.cell)

    def counter(self, can_id: int) -> int:
        self.counters[can_id] = (self.counters.get(can_id, -1) + 1) & 15
        return self.counters[can_id]

    def rx(self, can_id: int, data: bytes) -> None:
        self.ecu.isr_can_rx(can_id, data)
        self.ask(f"ecu_rx {can_id} {data.hex() or '-'}", "ok")

    def command(self) -> tuple[int, bytes]:
        can_id = self.rng.choice(secoc.SECURED_IDS)
        e = ErrorMask()
        if can_id == frames.NAV_GOAL_ID:
            field = self.rng.choice((0, 1, 2, 14))
            data = hf.pack_nav_goal(self.counter(can_id), field, 1000, e)
        elif can_id == frames.ODOM_SET_POSE_ID:
            field = self.rng.choice((0, 1, 2, 15, 7))
            data = hf.pack_odom_set_pose(
                self.counter(can_id), field, self.rng.randrange(9999), e
            )
        else:
            data = hf.pack_odom_config(self.counter(can_id), 3, 300_000_000, e)
        return can_id, data

    def auth(self, can_id: int, data: bytes, fv: int, mac: int | None = None) -> tuple[int, bytes]:
        tag = secoc.authenticator(self.mac_key, can_id, data, fv) if mac is None else mac
        request = secoc.SECURED_IDS.index(can_id)
        return frames.ODOM_AUTH_ID, hf.pack_odom_auth(
            self.counter(frames.ODOM_AUTH_ID), request, fv & 0xFFFF, tag
        )

    def recount(self, can_id: int, data: bytes) -> bytes:
        frame = bytearray(data)
        hf.p02_protect(frame, self.counter(can_id), hf.DATA_IDS_BY_FRAME_ID[can_id])
        return bytes(frame)

    def genuine(self) -> None:
        can_id, data = self.command()
        self.host_fv += 1
        pair = [(can_id, data), self.auth(can_id, data, self.host_fv)]
        self.recorded.append(pair)
        for frame in pair:
            self.rx(*frame)

    def forged(self) -> None:
        """Right freshness, random authenticator."""
        can_id, data = self.command()
        self.rx(can_id, data)
        self.rx(*self.auth(can_id, data, self.host_fv + 1, self.rng.getrandbits(32)))

    def replayed(self) -> None:
        """A recorded genuine command, with fresh E2E counters."""
        for can_id, data in self.rng.choice(self.recorded):
            if can_id == frames.ODOM_AUTH_ID:
                fields = secoc.unpack_odom_auth(data)
                self.rx(can_id, hf.pack_odom_auth(self.counter(can_id), *fields[1:]))
            else:
                self.rx(can_id, self.recount(can_id, data))

    def unsigned(self) -> None:
        """Unsigned (expires), or displaced by a second frame."""
        self.rx(*self.command())
        if self.rng.random() < 0.5:
            can_id, data = self.command()
            self.rx(can_id, data)
            self.rx(*self.auth(can_id, data, self.host_fv + 1))
            self.host_fv += 1

    def orphan(self) -> None:
        """An orphan ODOM_AUTH, or one naming no secured message."""
        pdu = bytearray(hf.pack_odom_auth(self.counter(frames.ODOM_AUTH_ID), 1, 0, 0))
        pdu[1] = (pdu[1] & 0x0F) | (self.rng.choice((1, 5, 15)) << 4)
        hf.p02_protect(pdu, pdu[1] & 15, frames.ODOM_AUTH_DATA_IDS)
        self.rx(frames.ODOM_AUTH_ID, bytes(pdu))

    def beyond_window(self) -> None:
        can_id, data = self.command()
        self.rx(can_id, data)
        self.rx(*self.auth(can_id, data, self.host_fv + 5000))

    def inject(self, roll: int) -> None:
        """The commands of one tick, by a roll in [0, 10): 8 and 9 (and 4 while nothing is
        recorded) send none."""
        if roll < 3:
            self.genuine()
        elif roll == 3:
            self.forged()
        elif roll == 4 and self.recorded:
            self.replayed()
        elif roll == 5:
            self.unsigned()
        elif roll == 6:
            self.orphan()
        elif roll == 7:
            self.beyond_window()

    def tick(self, tick: int) -> None:
        if tick == 200:
            self.ecu = self.boot()  # a reboot: RAM lost, the EPOCH cell kept
        self.count += 3
        self.rx(
            frames.WHEEL_ENCODERS_ID,
            sf.pack_wheel_encoders(tick & 15, self.count, self.count),
        )
        self.inject(self.rng.randrange(10))
        self.tx.sent.clear()
        ecu = self.ecu
        ecu.tick()
        self.ask(
            "ecu_tick", int(ecu.state), int(ecu.reason), ecu.errors.bits, ecu.tx_dropped,
            *self.tx.sent,
        )
        for entry in self.tx.sent:
            can_id_hex, data_hex = entry.split(":")
            if int(can_id_hex, 16) == frames.ODOM_FRESHNESS_ID:
                self.host_fv = hf.unpack_odom_freshness(bytes.fromhex(data_hex)).fv

    def run(self, ticks: int) -> None:
        for tick in range(ticks):
            self.tick(tick)
        assert self.ecu.secoc is not None
        rx_state = self.ecu.secoc.receiver
        self.ask(
            "ecu_secoc_counts",
            rx_state.count_ok,
            rx_state.count_failed,
            rx_state.count_freshness,
            self.ecu.secoc.orphans,
            rx_state.epoch,
            rx_state.last_fv,
        )


class _RecordingTx:
    """The Python ECU's CAN driver in the ECU sessions: records, or refuses when full."""

    def __init__(self) -> None:
        self.sent: list[str] = []
        self.full = False

    def transmit(self, can_id: int, data: bytes) -> bool:
        if self.full:
            return False
        self.sent.append(f"{can_id:X}:{data.hex().upper()}")
        return True


def _ecu_session(
    rng: random.Random,
    ask: Callable[..., None],
    robot: str,
    integrator: str,
    counts_per_rev: int | None = None,
    timed: bool = True,
    counter_bits: int | None = None,
) -> None:
    """The whole ECU, tick by tick: encoder frames from a kinematic robot driven by the ECU's own
    MOTOR_CMDs, navigation goals, pose and configuration writes, and faults (lost, repeated,
    corrupt, short and foreign frames, silence, mailbox overflow, bus-off, a full TX queue), and
    the health paths: forged steps beyond the maximum wheel speed (IMPLAUSIBLE_STEP), a motor
    controller reboot (counters and COUNTER restart: COUNTER_RESET, then ODOM_SET_POSE APPLY),
    and a second one its CTRL_UPTIME going back tells (its counters from 0: COUNTER_RESET again).

    ``timed``: every tick gets the board's u32 microsecond timer (``tick(now_us)``), released
    with jitter and wrapping during the session, and the MCU stalls now and then for 3 to 40
    periods, as sim/board.py models it: the wheels keep turning, the controller's 3-frame receive
    FIFO keeps the first frames and an overrun interrupt says it dropped others; a stall of 9
    periods or more is TIME_LOST. Untimed: ``tick()``, one period each."""
    params = firmware_params(load(robot), integrator)
    if counts_per_rev is not None:
        params = dataclasses.replace(params, counts_per_rev=counts_per_rev)
    if counter_bits is not None:
        params = dataclasses.replace(params, counter_bits=counter_bits)
    session = _EcuSession(rng, ask, params, timed)
    for tick in range(3_000):
        session.period(tick)


class _EcuSession:
    """One ECU session's state: the Python ECU, its kinematic robot and the host's counters."""

    def __init__(
        self,
        rng: random.Random,
        ask: Callable[..., None],
        params: config.RobotParams,
        timed: bool,
    ) -> None:
        self.rng, self.ask, self.timed = rng, ask, timed
        self.tx = _RecordingTx()
        self.ecu = OdomEcu(self.tx, params)
        ask(f"ecu_new {' '.join(str(v) for v in dataclasses.astuple(params))}", "ok")
        self.m_per_count = (
            2 * math.pi * params.wheel_radius_left_nm * 1e-9 / (params.counts_per_rev or 500)
        )
        wraps = params.counter_bits != 16  # the 24-bit wire wraps during the session
        self.counter_range = 1 << params.counter_bits  # a 16-bit counter sends 16 bits
        self.counts = [(1 << 24) - 300.0] * 2 if wraps else [0.0, 0.0]
        self.speeds = [0, 0]
        self.enc_counter = 0
        self.nominal_us = U32_MAX - rng.randrange(1_000_000, 5_000_000)  # the timer wraps
        self.stalls = {
            rng.randrange(100, 2900): rng.choice((3, 8, 9, 10, 14, 25, 40)) for _ in range(6)
        }
        self.reboot_tick = rng.randrange(1500, 2500)
        self.uptime = 0  # CTRL_UPTIME: 0 (not reported) until the reboot, then the age
        self.host_counters = {
            frames.NAV_GOAL_ID: 0, frames.ODOM_SET_POSE_ID: 0, frames.ODOM_CONFIG_ID: 0
        }

    def rx(self, can_id: int, data: bytes) -> None:
        self.ecu.isr_can_rx(can_id, data)
        self.ask(f"ecu_rx {can_id} {data.hex() or '-'}", "ok")

    def host(self, can_id: int, pack: Callable[[int], bytes]) -> None:
        counter = self.host_counters[can_id] = (self.host_counters[can_id] + 1) & 15
        self.rx(can_id, pack(counter))

    def goal(self) -> None:
        rng, e = self.rng, ErrorMask()
        for field, value in ((0, rng.randrange(-3000, 3000)), (1, rng.randrange(-3000, 3000))):
            pack = partial(hf.pack_nav_goal, field=field, value=value, errors=e)
            self.host(frames.NAV_GOAL_ID, pack)
        self.host(
            frames.NAV_GOAL_ID, lambda c: hf.pack_nav_goal(c, 2, rng.randrange(1 << 16), e)
        )
        go = (rng.randrange(2), rng.randrange(2), rng.randrange(2), rng.randrange(256))
        self.host(frames.NAV_GOAL_ID, lambda c: hf.pack_nav_goal_go(c, *go, e))

    def drive(self) -> list[int]:
        """10 ms of the wheels at the last MOTOR_CMD; the counters' wire value."""
        for side in range(2):
            self.counts[side] += self.speeds[side] * 1e-5 / self.m_per_count
        return [round(c) % self.counter_range for c in self.counts]

    def next_encoders(self, wire: list[int]) -> bytes:
        """The next WHEEL_ENCODERS frame (next COUNTER) carrying ``wire``."""
        self.enc_counter = (self.enc_counter + 1) & 15
        return sf.pack_wheel_encoders(self.enc_counter, wire[0], wire[1], self.uptime)

    def period(self, tick: int) -> None:
        """One encoder period: a stall, the motor controller's life, the frame, the host, a tick."""
        roll = self.rng.randrange(1000)
        stall = self.stalls.get(tick, 0) if self.timed else 0
        self.stall(stall)
        self.nominal_us += (stall + 1) * 10_000
        self.motor_controller_life(tick)
        wire = self.drive()
        silent = 1200 <= tick < 1220  # the watchdog: DEGRADED, then recovery
        if not silent and roll >= 20:
            self.encoders(roll, wire)
        self.inputs(tick, roll, wire)
        self.tick()

    def stall(self, periods: int) -> None:
        """The MCU does not run: frames pile up in the controller's FIFO; as sim/board.py's bxCAN
        (FIFO-locked) the first 3 are kept and an overrun interrupt follows."""
        backlog = [self.next_encoders(self.drive()) for _ in range(periods)]
        for frame in backlog[:3]:
            self.rx(frames.WHEEL_ENCODERS_ID, frame)
        if len(backlog) > 3:
            self.ecu.isr_rx_overrun()
            self.ask("ecu_overrun", "ok")

    def motor_controller_life(self, tick: int) -> None:
        """The motor controller reboots (counters and COUNTER restart); 40 ticks later the host
        gives the pose again, so COUNTER_RESET may clear."""
        if tick == self.reboot_tick:
            offset = self.rng.choice((-1, 1)) * self.rng.randrange(5_000, 20_000)
            self.counts[:] = [self.counts[0] + offset, self.counts[1] + offset]
            self.enc_counter = 15
        if tick == self.reboot_tick + 250:  # a reboot told by CTRL_UPTIME: counters from 0
            self.counts[:] = [float(self.rng.randrange(8)), float(self.rng.randrange(8))]
            self.enc_counter = 15
        if tick >= self.reboot_tick:  # from here the controller reports its age
            since = tick - self.reboot_tick - (250 if tick >= self.reboot_tick + 250 else 0)
            self.uptime = min(15, 1 + since // 100)
        if tick in (self.reboot_tick - 600, self.reboot_tick - 300):
            # A bus that held the encoder frames back lets them out back to back: the mailbox
            # keeps 32, drops the rest (18 and 35 with the period's own: whole COUNTER cycles).
            for _ in range(49 if tick < self.reboot_tick - 300 else 66):
                self.rx(frames.WHEEL_ENCODERS_ID, self.next_encoders(self.drive()))
            for _ in range(3):  # a babbler's frames on the ID, dropped too (counted, not ours)
                self.rx(frames.WHEEL_ENCODERS_ID, bytes([0xA5]) + self.rng.randbytes(7))
        if tick == self.reboot_tick + 20:  # a later cause must not hide COUNTER_RESET (a burst)
            for _ in range(40):
                self.rx(0x555, bytes(8))
        if tick == self.reboot_tick + 40:
            self.host(
                frames.ODOM_SET_POSE_ID,
                lambda c: hf.pack_odom_set_pose(c, frames.SetPoseField.APPLY, 0, ErrorMask()),
            )

    def encoders(self, roll: int, wire: list[int]) -> None:
        """This period's encoder frame, corrupt or repeated by ``roll``."""
        frame = self.next_encoders(wire)
        if roll < 40:
            frame = bytes([frame[0] ^ 1]) + frame[1:]  # corrupt
        self.rx(frames.WHEEL_ENCODERS_ID, frame)
        if roll < 50:
            self.rx(frames.WHEEL_ENCODERS_ID, frame)  # repeated

    def inputs(self, tick: int, roll: int, wire: list[int]) -> None:
        """Host commands and bus faults by ``roll``."""
        rng = self.rng
        if roll < 1 or tick % 500 == 1:
            self.goal()
        elif roll < 2 and tick % 3 == 0:
            self.host(frames.NAV_GOAL_ID, lambda c: hf.pack_nav_goal(c, 14, 0, ErrorMask()))
        elif roll < 5:
            self.set_pose_field()
        elif roll < 18:
            self.config_param()
        elif roll < 25 or (self.tx.full and roll < 500):
            self.faults(roll, wire)
        elif roll < 28:  # a step beyond the maximum wheel speed that passes E2E (a forgery)
            self.enc_counter = (self.enc_counter + 1) & 15
            jump = rng.choice((-1, 1)) * rng.randrange(200, 30_000)
            forged = [(w + jump) % (1 << 32) for w in wire]
            self.rx(frames.WHEEL_ENCODERS_ID,
                    sf.pack_wheel_encoders(self.enc_counter, forged[0], forged[1], self.uptime))

    def set_pose_field(self) -> None:
        field = self.rng.choice((0, 1, 2, 15, 15, 7))
        value = self.rng.randrange(-100_000, 100_000) if field < 2 else self.rng.randrange(1 << 16)
        self.host(
            frames.ODOM_SET_POSE_ID,
            partial(hf.pack_odom_set_pose, field=field, value=value, errors=ErrorMask()),
        )

    def config_param(self) -> None:
        rng = self.rng
        param = rng.choice((0, 0, 1, 2, 3, 4, 5, 6, 6, 15, 15, 15, 9))
        by_param = {
            0: rng.choice((500, 2578, 0, 500)),
            4: rng.choice((16, 32)),
            5: rng.randrange(3),
            6: rng.choice((700, 1_200, 4_000, 0, 65_535)),  # MAX_WHEEL_SPEED, mm/s (0: NACK)
        }
        by_param.update({1: 75_000_000, 2: rng.choice((75_000_000, 35_000_000)), 3: 300_000_000})
        v = by_param.get(param, 0)
        if (param, v) == (6, 0):  # outside the DBC's range: sent raw, the firmware NACKs it
            self.host(frames.ODOM_CONFIG_ID, partial(hf.pack_odom_config_raw, param=6, raw=0))
            return
        self.host(
            frames.ODOM_CONFIG_ID,
            partial(hf.pack_odom_config, param=param, value=v, errors=ErrorMask()),
        )

    def faults(self, roll: int, wire: list[int]) -> None:
        """Foreign, short and bursting frames, bus-off, a full TX queue (``roll`` 18 to 24, or
        below 500 while the queue is full)."""
        rng = self.rng
        if roll < 20:
            self.rx(rng.choice((0x123, frames.ODOM_POSE_X_ID)), rng.randbytes(8))  # not for us
        elif roll < 21:
            self.rx(frames.NAV_GOAL_ID, rng.randbytes(rng.randrange(8)))  # short
        elif roll < 22:
            for _ in range(40):  # a burst: the mailbox overflows
                self.rx(0x555, bytes(8))
        elif roll < 23:
            self.ecu.isr_bus_state(rng.random() < 0.5)
            self.ask(f"ecu_bus {int(self.ecu.errors.has(ErrorFlag.BUS_OFF))}", "ok")
        else:
            self.tx.full = not self.tx.full  # a full TX queue for a tick or two
            self.ask(f"ecu_txfull {int(self.tx.full)}", "ok")

    def tick(self) -> None:
        """The ECU's tick (timed: at the jittered timer), its answer, and the wheels' new speeds
        from any MOTOR_CMD it sent."""
        ecu, tx = self.ecu, self.tx
        tx.sent.clear()
        if self.timed:
            now_us = (self.nominal_us + self.rng.randrange(-3_000, 3_001)) % (1 << 32)  # jitter
            ecu.tick(now_us)
            tick_cmd = f"ecu_tick_at {now_us}"
        else:
            ecu.tick()
            tick_cmd = "ecu_tick"
        state, reason = int(ecu.state), int(ecu.reason)
        self.ask(tick_cmd, state, reason, ecu.errors.bits, ecu.tx_dropped, *tx.sent)
        for entry in tx.sent:
            can_id, data = entry.split(":")
            if int(can_id, 16) == frames.MOTOR_CMD_ID:
                cmd = sf.unpack_motor_cmd(bytes.fromhex(data))
                self.speeds = [cmd.left_speed_mm_s, cmd.right_speed_mm_s]


def _frames(rng: random.Random, ask: Callable[..., None]) -> None:
    """The cantools-generated C (dbc/odocan.c) against firmware/frames.py's own packers."""
    for _ in range(2_000):
        counter, left, right = rng.randrange(16), rng.getrandbits(32), rng.getrandbits(32)
        frame = sf.pack_wheel_encoders(counter, left, right)
        ask(f"enc_pack {counter} {left} {right}", frame.hex().upper())
        aged = sf.pack_wheel_encoders(counter, left, right, rng.randrange(16))
        junk = rng.randbytes(8)
        for data in (frame, aged, junk):
            ask(f"enc_unpack {data.hex()}", *frames.unpack_wheel_encoders(data))
        speeds = [rng.randrange(I16_MIN, I16_MAX + 1) for _ in range(2)]
        motor = frames.pack_motor_cmd(counter, speeds[0], speeds[1], ErrorMask())
        ask(f"motor_pack {counter} {speeds[0]} {speeds[1]}", motor.hex().upper())
        field = rng.choice((0, 1, 2, 14, 15, rng.randrange(16)))
        if field == NavGoalField.GO:
            go = (rng.randrange(2), rng.randrange(2), rng.randrange(2), rng.randrange(256))
            goal = hf.pack_nav_goal_go(counter, *go, ErrorMask())
        else:
            value = rng.randrange(I32_MIN, I32_MAX + 1)
            goal = hf.pack_nav_goal(counter, field, value, ErrorMask())
        ask(f"goal_unpack {goal.hex()}", *frames.unpack_nav_goal(goal))


def _nav_functions(rng: random.Random, ask: Callable[..., None]) -> None:
    """Every pure function of firmware/nav.py on random and extreme inputs."""
    big = [I64_MIN, I64_MAX, 0, -1, 1 << 51, -(1 << 51)]
    pairs = [(rng.randrange(I64_MIN, I64_MAX + 1) >> rng.randrange(64), 0) for _ in range(2_000)]
    pairs = [(dx, rng.randrange(I64_MIN, I64_MAX + 1) >> rng.randrange(64)) for dx, _ in pairs]
    pairs += list(itertools.product(big, big))
    for dx, dy in pairs:
        errors = ErrorMask()
        ask(f"dist {dx} {dy}", nav.distance_um(dx, dy, errors), errors.bits)
        h = rng.getrandbits(32)
        ask(f"bearing {dx} {dy} {h}", nav.bearing_error_bam32(dx, dy, h))
    angles = [rng.randrange(I32_MIN, I32_MAX + 1) for _ in range(2_000)] + [I32_MIN, I32_MAX, 0]
    for a in angles:
        k = rng.choice((nav.K_TURN_MILLI_PER_S, nav.K1_MILLI_PER_S, rng.randrange(0, 5000)))
        errors = ErrorMask()
        ask(f"turn {a} {k}", nav.turn_rate_mrad_s(a, k, errors), errors.bits)
        d = rng.randrange(-(1 << 44), 1 << 44) >> rng.randrange(44)
        ask(f"speed {d} {k}", nav.speed_mm_s(d, k))
        for law in ("gtg", "straight"):
            errors = ErrorMask()
            fn = nav.go_to_goal_law if law == "gtg" else nav.drive_straight_law
            ask(f"{law} {abs(d)} {a}", *fn(abs(d), a, errors), errors.bits)
        v, w = rng.randrange(-600, 601), rng.randrange(-2500, 2501)
        b = rng.randrange(10_000_000, 4_000_000_001)
        ask(f"wheels {v} {w} {b}", *nav.wheel_speeds_mm_s(v, w, b))
        t, p = rng.randrange(-3000, 3001), rng.randrange(-3000, 3001)
        ask(f"rate {t} {p}", nav.rate_limit(t, p))
        q = rng.randrange(I32_MIN, I32_MAX + 1) >> rng.randrange(32)
        ask(f"q40 {q}", nav.q40_from_100um(q))
    for q in (I32_MIN, I32_MAX, -1, -10_000, -10_001, 9_999, 10_000, 5_000, -5_000):
        ask(f"q40 {q}", nav.q40_from_100um(q))
    # the rim limits at the extremes: a 1 cm turn in place at one step, a 2 m and 4 m one capped
    for v, w, b in ((0, 1, 10_000_000), (0, -3, 10_000_000), (3, 1, 10_000_000),
                    (0, 2000, 2_000_000_000), (0, -2500, 4_000_000_000),
                    (500, -2000, 2_000_000_000)):
        ask(f"wheels {v} {w} {b}", *nav.wheel_speeds_mm_s(v, w, b))


def _nav_session(rng: random.Random, ask: Callable[..., None]) -> None:
    """A navigator driving a simple kinematic robot through goals, stops, aborts and junk.

    The test moves the robot from the setpoints (float kinematics, then quantised): both
    firmwares get the same integer pose each period and must give the same answers."""
    navigator = nav.Navigator(ErrorMask())
    ask("nav_new", "ok")
    x_m = y_m = th_rad = 0.0
    b_nm = rng.choice((300_000_000, 230_000_000, rng.randrange(100_000_000, 1_000_000_000),
                       10_000_000, 2_000_000_000, rng.randrange(10_000_000, 4_000_000_001)))
    # one encoder count's heading step: pmir's (2^64 / 2000), a 1 cm robot's, any up to 2^60
    count_bam64 = rng.choice(((1 << 64) // 2000, 1 << 58, rng.randrange(1 << 60)))
    running = True

    def send(field: NavGoalField | int, value: int, go: tuple[int, int, int, int] = (0,) * 4):
        frame = NavGoal(0, field, value, *go)
        reason = navigator.request(frame, running)
        ask(f"nav_req {int(field)} {value} {' '.join(map(str, go))} {int(running)}", int(reason))

    def goal(append: bool) -> None:
        fields = [(NavGoalField.X, rng.randrange(-10_000, 10_000))]
        fields += [(NavGoalField.Y, rng.randrange(-10_000, 10_000))]
        fields += [(NavGoalField.HEADING, rng.randrange(1 << 16))]
        if rng.random() < 0.05:
            fields.pop(rng.randrange(3))  # INCOMPLETE (or fine without a heading)
        for field, value in fields:
            send(field, value)
        mode = rng.choice((0, 0, 0, 1, 1, 1, 2))  # 2: OUT_OF_RANGE
        send(NavGoalField.GO, 0, (mode, int(append), int(rng.random() < 0.3), rng.randrange(256)))

    for _ in range(1_500):
        roll = rng.randrange(1000)
        _nav_requests(rng, roll, navigator, goal, send)
        if running and roll >= 997:
            running = False
        elif not running and rng.random() < 0.1:
            running = True
        x, y = round(x_m * 2**40), round(y_m * 2**40)
        h = round(th_rad / (2 * math.pi) * 2**64) % 2**64
        sent = navigator.step(x, y, h, b_nm, count_bam64, running)
        ask(
            f"nav_step {x} {y} {h} {b_nm} {count_bam64} {int(running)}",
            int(sent),
            navigator.left_mm_s,
            navigator.right_mm_s,
            int(navigator.state),
            navigator.goal_id,
            navigator.depth,
            navigator.distance_um,
            navigator.heading_error_bam32,
            int(navigator.changed),
            navigator._errors.bits,
        )
        navigator.changed = False
        if running:  # 20 ms of the kinematic robot at the setpoints
            v_m_s = (navigator.left_mm_s + navigator.right_mm_s) / 2000
            w_rad_s = (navigator.right_mm_s - navigator.left_mm_s) / (b_nm / 1e6)
            th_rad += w_rad_s * 0.02
            x_m += v_m_s * 0.02 * math.cos(th_rad)
            y_m += v_m_s * 0.02 * math.sin(th_rad)


def _nav_requests(
    rng: random.Random,
    roll: int,
    navigator: nav.Navigator,
    goal: Callable[..., None],
    send: Callable[..., None],
) -> None:
    """One period's host requests by ``roll``: a goal when idle, appended goals, a path that
    overflows the queue, STOP and an unknown field."""
    idle = navigator.state in (NavState.IDLE, NavState.STOPPED, NavState.ABORTED)
    if (idle or (navigator.state == NavState.REACHED and not navigator.depth)) and roll < 200:
        goal(append=rng.random() < 0.5)
    elif roll < 8:
        goal(append=True)
    elif roll < 9:
        for _ in range(17):  # a full path, then QUEUE_FULL
            goal(append=True)
    elif roll < 11:
        send(rng.choice((NavGoalField.STOP, 7)), 0)


def _e2e_session(rng: random.Random, ask: Callable[..., None]) -> None:
    """A receiver fed protected frames with losses, repeats, jumps, corruption and silence."""
    data_ids = bytes(rng.getrandbits(8) for _ in range(16))
    init, per_period = rng.randrange(0, 15), rng.random() < 0.5
    rx = e2e.E2EReceiver(tuple(data_ids), init, window_per_period=per_period)
    ask(f"rx {data_ids.hex()} {init} {int(per_period)}", "ok")

    def state(status: e2e.E2EStatus) -> tuple[int, ...]:
        counts: tuple[int, ...] = (
            rx.count_ok, rx.count_oksomelost, rx.count_repeated, rx.count_wrongsequence
        )
        counts += (rx.count_error, rx.count_nonewdata, rx.lost_frames)
        window = (rx.last_valid_counter, rx.max_delta_counter, rx.lost_data, rx.accepted())
        return (int(status), *counts, *window)

    counter = rng.randrange(16)
    for _ in range(300):
        action = rng.randrange(100)
        if action < 8:
            rx.new_period()
            ask("period", "ok")
        elif action < 10:
            rx.reset()
            ask("reset", "ok")
        elif action < 18:
            ask("check -", *state(rx.check(None)))
        else:
            frame = bytearray(rng.randbytes(8))
            counter = (counter + rng.choice((0, 1, 1, 1, 1, 2, 3, 7, 15))) & 15
            hf.p02_protect(frame, counter, tuple(data_ids))
            ask(f"protect {frame.hex()} {counter}", frame.hex().upper())
            if action < 24:
                frame[rng.randrange(8)] ^= 1 << rng.randrange(8)
            elif action < 27:
                frame = frame[: rng.randrange(8)] or bytearray(b"\x00")
            ask(f"check {frame.hex()}", *state(rx.check(frame)))


def test_the_probe_script_reaches_every_state_and_reason() -> None:
    cmds, want = _probe_script(seed=12)
    steps = [w.split() for c, w in zip(cmds, want, strict=True) if c.startswith("nav_step")]
    acks = {int(w) for c, w in zip(cmds, want, strict=True) if c.startswith("nav_req")}
    assert {int(s[3]) for s in steps} == set(NavState)
    assert acks >= {0, 1, 2, 3, 4, 6}  # every reason NAV_GOAL can get (INCONSISTENT is config's)
    checks = {int(w.split()[0]) for c, w in zip(cmds, want, strict=True) if c.startswith("check")}
    assert checks == {int(s) for s in e2e.E2EStatus}
    ticks = [w.split() for c, w in zip(cmds, want, strict=True) if c.startswith("ecu_tick")]
    assert {int(t[0]) for t in ticks} == {0, 1, 2, 3}  # INIT, OK, DEGRADED, FAULT
    assert {int(t[1]) for t in ticks} == set(Reason), "every REASON, CONFIG_INVALID included"
    assert any(c.startswith("ecu_tick_at") for c in cmds)
    assert "ecu_tick" in cmds
    health = ErrorFlag.TIME_LOST | ErrorFlag.IMPLAUSIBLE_STEP | ErrorFlag.COUNTER_RESET
    assert all(any(int(t[2]) & flag for t in ticks) for flag in health)
    states = [(int(t[0]), int(t[1])) for t in ticks]
    # one ECU's ticks: an ecu_new between two ticks starts another (FAULT for invalid params)
    born = list(itertools.accumulate(
        c.startswith("ecu_new") for c in cmds))
    lives = [born[i] for i, c in enumerate(cmds) if c.startswith("ecu_tick")]
    recovered = [
        after
        for (before, after), (a, b) in zip(itertools.pairwise(states),
                                           itertools.pairwise(lives), strict=True)
        if a == b and before == (State.DEGRADED, Reason.COUNTER_RESET)
        and after[0] != State.DEGRADED
    ]
    assert recovered
    assert all(after == (State.OK, Reason.NONE) for after in recovered)
    resets = [
        after
        for before, after in itertools.pairwise(states)
        if after == (State.DEGRADED, Reason.COUNTER_RESET) and before != after
    ]
    assert len(resets) >= 2 * 5, "5 driving sessions: a reboot by the counts, one CTRL_UPTIME tells"
    lost = [
        i
        for i in range(1, len(ticks))
        if int(ticks[i][1]) == Reason.TIME_LOST != int(ticks[i - 1][1])
    ]
    twists_after_gap = [
        hf.unpack_odom_twist(bytes.fromhex(f.split(":")[1])).linear_vel_mm_s
        for i in lost
        for t in ticks[i : i + 3]
        for f in t[4:]
        if f.startswith(f"{frames.ODOM_TWIST_ID:X}:")
    ]
    assert len(lost) >= 5, "stalls while driving: the twist after a gap"
    assert any(twists_after_gap), "stalls while driving: the twist after a gap"
    sent = {f.split(":")[0] for t in ticks for f in t[4:]}
    assert sent == {"110", "200", "201", "202", "281", "302", "304", "380"}
    reasons = {
        hf.unpack_odom_ack(bytes.fromhex(f.split(":")[1])).reason
        for t in ticks
        for f in t[4:]
        if f.startswith("302:")
    }
    assert {r for r in frames.AckReason if r.name.startswith("AUTH_")} <= reasons
    counts = [w.split() for c, w in zip(cmds, want, strict=True) if c == "ecu_secoc_counts"]
    accepted, failed, stale, orphans, epoch = (int(v) for v in counts[0][:5])
    assert accepted > 20
    assert failed > 5
    assert stale > 5
    assert orphans > 5
    assert epoch == 2
    assert max(int(t[3]) for t in ticks) > 0, "the TX queue refused frames"


@pytest.mark.parametrize("target", ["native", "arm32"])
def test_every_function_answers_as_the_python_firmware(target: str, tmp_path: Path) -> None:
    if target == "native":
        _require("make", "gcc")
        binary, runner = tmp_path / "probe", []
    else:
        _require("make", "arm-linux-gnueabihf-gcc", "qemu-arm")
        binary, runner = tmp_path / "probe_arm", ["qemu-arm", "-L", "/usr/arm-linux-gnueabihf"]
    built = _make(f"BUILD={tmp_path}", str(binary))
    assert built.returncode == 0, built.stderr
    cmds, want = _probe_script(seed=12)
    result = subprocess.run(
        [*runner, str(binary)], input="\n".join(cmds) + "\n", capture_output=True, text=True
    )
    assert result.returncode == 0, result.stderr[-2000:]
    got = result.stdout.splitlines()
    assert len(got) == len(want)
    wrong = [(c, w, g) for c, w, g in zip(cmds, want, got, strict=True) if w != g]
    assert not wrong, f"{len(wrong)} of {len(cmds)} differ, first: {wrong[:3]}"
