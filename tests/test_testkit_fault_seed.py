"""The fault streams of ``odocan_rig`` and ``odocan firmware`` follow their seed (issue #11).

``odocan run --seed N`` draws its faults from N unless the spec sets ``seed=``; the pytest kit
drew them from 0 at every ``seed`` (a sweep of seeds met one drop pattern), and ``odocan
firmware`` had no ``--seed`` at all. Checked on which WHEEL_ENCODERS frames reach the bus
through ``drop=0.3``: a standstill rig's frames differ only by the drops."""

from __future__ import annotations

import pytest

from odocan.host.cli.app import build_parser, main
from odocan.host.io.buses import parse_faults
from odocan.host.testkit.options import RigOptions
from odocan.host.testkit.rig import make_rig


def _kept_stamps(faults: str, seed: int) -> list[float]:
    rig = make_rig(RigOptions(faults=faults, seed=seed))
    try:
        rig.step(1.0)
        return [frame["timestamp_s"] for frame in rig.frames("WHEEL_ENCODERS")]
    finally:
        rig.close()


def test_the_kits_drops_follow_its_seed_unless_the_spec_sets_one() -> None:
    one, again, two = (_kept_stamps("drop=0.3", 1), _kept_stamps("drop=0.3", 1),
                       _kept_stamps("drop=0.3", 2))
    assert 50 < len(one) < 95  # ~70 of 100 kept
    assert one == again  # one seed, one stream
    assert one != two
    assert _kept_stamps("drop=0.3,seed=9", 1) == _kept_stamps("drop=0.3,seed=9", 2)


def test_the_firmware_command_takes_a_seed_for_its_faults(
    capsys: pytest.CaptureFixture[str],
) -> None:
    args = build_parser("firmware").parse_args(
        ["firmware", "--seed", "7", "--faults", "drop=0.1"])
    spec = parse_faults(args)
    assert spec is not None
    assert spec.seed == 7
    assert main(["firmware", "-i", "virtual", "-c", "odocan-fault-seed", "--duration", "0.1",
                 "--seed", "3", "--faults", "drop=0.1"]) == 0
    assert "error" not in capsys.readouterr().err
