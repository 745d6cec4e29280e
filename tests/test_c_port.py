"""The C port (firmware/c): bit-exact against the golden vectors, natively and on 32-bit ARM.

``make -C firmware/c check`` builds the port natively with UBSan + ASan and as a static 32-bit ARM
Linux binary run under qemu-arm, and replays over 10^6 steps of vectors (both robot profiles, the
three integrators, counter wraps) from the JSON and the CSV files. The tests skip with the reason
when a tool is missing, except under ``CI=true``, where a missing tool is a failure.
"""

from __future__ import annotations

import itertools
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from odocan.firmware.fixmath import wrap_signed
from odocan.host.cli.app import main
from odocan.host.judge import vectors
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
        sets = {name for name, *_ in lines}
        assert sets == {f"{r}_{i}" for r in ("pmir", "kobuki") for i in ("euler", "rk2", "exact")}
        assert all(json == csv and mismatches == "0" for _, json, csv, mismatches in lines)
        assert sum(int(csv) for _, _, csv, _ in lines) >= 1_000_000


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
    bad = subprocess.run([str(build / "vectors_check"), str(bad_json)], capture_output=True)
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
    assert len(case.counts) == 3001 and all(0 <= c < 1 << 16 for pair in case.counts for c in pair)
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
    assert capsys.readouterr().err.startswith("error: --random-steps must be >= 0")
