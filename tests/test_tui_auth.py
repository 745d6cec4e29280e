"""The monitor's screen draws the SecOC refusals: a lockstep rig whose firmware holds a key is
attacked (forged authenticators, an unsigned command, ODOM_AUTH frames after no command), every
host-bus frame feeds the monitor's model, and the 80x24 screen is read as text."""

from __future__ import annotations

import random

import can

from odocan.firmware import frames as fr
from odocan.firmware.errors import ErrorMask
from odocan.host.judge.monitor import BusMonitor
from odocan.host.report.trace import Trace
from odocan.host.report.tui import auth_text, firmware_line
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.robot import load
from tests import host_frames as hf
from tests.test_secoc_rig import (
    KEY,
    REQUEST,
    Bus,
    Counters,
    any_command,
    set_pose,
    step,
    synced_signer,
)
from tests.test_tui import Fed, draw


def attacked() -> Fed:
    """A genuine command, 5 forged ones, 1 unsigned set_pose (3 frames), 2 orphan ODOM_AUTH."""
    bus = Bus()
    heard: list[can.Message] = []
    with LockstepRig(RigConfig(load("pmir"), scenario=None, secoc_key=KEY), [bus]) as rig:
        signer = synced_signer(rig, bus)
        heard += bus.take()
        host, rng = Counters(), random.Random(5)
        heard += step(rig, bus, signer.secure(set_pose(host, 1_000, 0)))
        assert signer.next_fv is not None
        for _ in range(5):
            can_id, data = any_command(host, rng)
            auth = hf.pack_odom_auth(host(fr.ODOM_AUTH_ID), REQUEST[can_id],
                                     signer.next_fv & 0xFFFF, rng.getrandbits(32), ErrorMask())
            heard += step(rig, bus, [(can_id, data), (fr.ODOM_AUTH_ID, auth)])
        heard += step(rig, bus, set_pose(host, 5, 5))
        for _ in range(2):
            auth = hf.pack_odom_auth(host(fr.ODOM_AUTH_ID), 2, 0, 7, ErrorMask())
            heard += step(rig, bus, [(fr.ODOM_AUTH_ID, auth)])
        for _ in range(20):
            heard += step(rig, bus)
    model = BusMonitor(load("pmir"))
    trace = Trace(model.db)
    for msg in heard:
        model.feed(msg, now_s=msg.timestamp)
        trace.feed(msg)
    return Fed(model, trace, heard[-1].timestamp)


def test_the_firmware_line_counts_each_kind_of_refusal_on_80_columns() -> None:
    fed = attacked()
    rows = draw(fed, fed.view())
    assert len(rows) == 24
    assert rows[2].startswith("firmware OK  AUTH 5 failed 3 missing 2 orphan  reason ")
    assert all(len(r.rstrip()) <= 80 for r in rows)
    assert rows[7].startswith("event: ")  # the latest refusal, with what was refused
    assert "kind auth" in rows[7]
    assert "AUTH_MISSING" in rows[7]


def test_the_auth_segment_stays_on_a_stale_firmware_line_and_before_the_status() -> None:
    fed = attacked()
    stale = draw(fed, fed.view(silent_s=5.0))
    assert stale[2].startswith("firmware OK STALE  AUTH 5 failed 3 missing 2 orphan  reason ")
    snapshot = fed.model.snapshot(now_s=fed.last_s)
    snapshot["status"] = {}  # no ODOM_STATUS heard: the refusals are still drawn
    assert firmware_line(snapshot, None).plain == (
        "firmware no ODOM_STATUS summary yet  AUTH 5 failed 3 missing 2 orphan"
    )


def test_no_refusal_no_auth_segment() -> None:
    assert auth_text({"auth": {"auth_failed": 0, "auth_missing": 0}}) == ""
    assert auth_text({}) == ""  # a model that counts none
    assert auth_text({"auth": {"auth_freshness": 2, "auth_unavailable": 1}}) == (
        "AUTH 2 stale 1 unavailable"
    )
