"""``odocan monitor`` judged with the wrong ``--robot`` names the profile it judged with.

Found in a user trial: a kobuki firmware on udp_multicast, watched by ``odocan monitor`` without
``--robot`` (default pmir), ended ``monitor: FAIL: the on-board pose was wrong in 1 episode ...,
worst 2910.74 mm`` and exit 1: a correct firmware blamed, with no word of the profile the
reference used. ``analyze`` of the same log says ``robot mismatch``. The FAIL line now says which
profile the reference used, and with ``--log`` which shipped profile the heard poses fit.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.test_cli_monitor import BOUND, Source, source  # noqa: F401 (the fixture)
from tests.test_cli_run import run_cli


def test_a_monitor_on_the_wrong_robot_names_the_one_that_fits(
    source: Source,  # noqa: F811 (the fixture)
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    source.garbage = False  # a pmir firmware (the Source's rig), watched as kobuki
    log = tmp_path / "heard.log"
    code, _, err = run_cli(capsys, "monitor", "-i", "virtual", "-c", source.channel,
                           "--duration", BOUND, "--json", "--robot", "kobuki", "--log", str(log))
    assert code == 1
    assert err.startswith("monitor: FAIL: the on-board pose was wrong in "), err
    assert "judged as robot 'kobuki' (--robot)" in err, err
    assert "robot mismatch: the heard poses fit robot 'pmir', not 'kobuki'" in err, err
