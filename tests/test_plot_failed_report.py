"""A ``--plot`` that cannot be written leaves no ``--report`` saying PASS (trial finding F5).

With ``ulimit -f 20``, ``odocan analyze drive.log --report r.json --plot p.png`` wrote the
report (``passed: true``), then failed on the plot (exit 2): a CI step reading the report saw a
PASS the command did not give. Now the report is written last and says the plot failed
(``output_failed``, ``passed`` false), as ``run``'s report says a failed ``--log`` recording
(``recording``). The failure is made as in ``test_partial_output``: RLIMIT_FSIZE with SIGXFSZ
ignored, so a write past the limit fails with EFBIG."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from tests.limited import run_limited

LIMIT_BYTES = 20 * 1024  # the report (about 5 KB) fits, the plot (a PNG of 100 KB) does not


def test_a_failed_plot_leaves_a_report_that_does_not_pass(tmp_path: Path) -> None:
    log = tmp_path / "drive.log"
    subprocess.run([sys.executable, "-m", "odocan", "run", "--robot", "kobuki", "--duration",
                    "2", "--log", str(log)], capture_output=True, text=True, timeout=300,
                   check=True)
    report, plot = tmp_path / "r.json", tmp_path / "p.png"
    done = run_limited(["analyze", str(log), "--robot", "kobuki", "--report", str(report),
                        "--plot", str(plot)], file_bytes=LIMIT_BYTES)
    assert "PASS" in done.stdout  # the poses' verdict, printed first
    assert done.returncode == 2
    assert done.stderr.splitlines()[-1].startswith(f"error: --plot {plot}: ")
    assert not plot.exists()
    written = json.loads(report.read_text())
    assert written["passed"] is False
    assert written["output_failed"].startswith(f"--plot {plot}: ")
