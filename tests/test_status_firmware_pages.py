"""``status.firmware``: the firmware's last ODOM_STATUS page of each name, every signal but the
page's CHECKSUM, COUNTER and PAGE by its lower-case name, enums by their DBC names, CRCs as 0x….

The bridge names the pages when ``status`` reads them (once a second), no longer per page
heard (20 a second per robot), so the telemetry keeps each page's raw signals: here, after
every frame of a rig run, ``RobotTelemetry.firmware`` must equal what cantools (the DBC's own
decoder, ``decode_choices``) makes of the latest page of each name heard so far, and the
``status`` publication must carry the same."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, cast

import can
from cantools.database.namedsignalvalue import NamedSignalValue

from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim import robot
from odocan.sim.contract import database
from odocan.sim.rig import LockstepRig, RigConfig

PMIR = robot.load("pmir")
SKIPPED = ("CHECKSUM", "COUNTER", "PAGE")


def _page(data: bytes) -> tuple[str, dict[str, Any]]:
    """An ODOM_STATUS payload's page name and fields, by cantools alone."""
    message = database().get_message_by_name("ODOM_STATUS")
    decoded = cast(Mapping[str, Any], message.decode(data, decode_choices=True))
    fields = {name.lower(): str(v) if isinstance(v, NamedSignalValue) else v
              for name, v in decoded.items() if name not in SKIPPED}
    for name in [n for n in fields if n.endswith("_crc")]:  # docs/mqtt.md: 0x and 8 hex digits
        fields[name] = f"0x{int(fields[name]):08X}"
    return str(decoded["PAGE"]).lower(), fields


def test_status_firmware_is_each_page_latest_named() -> None:
    telemetry = RobotTelemetry("r", Geometry.of(PMIR), "exact", counter_bits=PMIR.counter_bits,
                               publish_hz=10)
    status_id = database().get_message_by_name("ODOM_STATUS").frame_id
    expected: dict[str, dict[str, Any]] = {}
    checked = [0]

    class Feed(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            telemetry.feed(msg)
            if msg.arbitration_id == status_id:
                name, fields = _page(bytes(msg.data))
                expected[name] = fields
                assert telemetry.firmware == expected
                checked[0] += 1

    config = RigConfig(robot=PMIR, seed=5, channel="test-status-pages", scenario="random",
                       duration_s=4.0)
    with LockstepRig(config, [Feed()]) as rig:
        rig.run()
    assert checked[0] > 50  # pages came again and again
    assert len(expected) >= 4  # of every name
    assert telemetry.status()[1]["firmware"] == expected
    assert expected["summary"]["state"] == "OK"  # an enum by its DBC name
