"""Every MQTT client id the bridge and the fleet use fits MQTT 3.1.1's 23 bytes, and is unique
per robot, per shard and per worker process (#13).

MQTT 3.1.1 obliges a broker to accept client ids of 1-23 bytes only; the command readers' ids
were ``<prefix>-<robot>-cmd`` (``odocan-bridge-robot001-cmd``: 26), a robot named by its
operator may take 64 characters, and the benches' prefixes carry a nanosecond clock. Checked
here against the shipped formats: the default prefix, the fleet's robot names
(``sim.fleet.robot_name``) of fleets split by ``--shard K/N`` and over ``--workers`` as
``host.mqtt.shards`` splits them (one bridge, so one command reader, per worker process), and
the ids a ``Bridge`` gives its links and its reader.
"""

from __future__ import annotations

import can
import pytest

from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.bridge import Bridge, BridgeConfig, RobotEndpoint
from odocan.host.mqtt.broker import BrokerURL
from odocan.host.mqtt.clientids import MAX_CLIENT_ID_BYTES, link_client_id, reader_client_id
from odocan.host.mqtt.shards import Shard, split
from odocan.sim import robot
from odocan.sim.fleet import robot_name

DEFAULT_PREFIX = "odocan-bridge"  # ``--client-prefix``'s default
PMIR = robot.load("pmir")


def _fleet_ids(total: int, shards: int, workers: int, prefix: str) -> list[str]:
    """Every client id of a fleet of ``total`` robots run as ``shards`` machines (``--shard
    K/N``), each with ``workers`` worker processes: per worker, its links' and its reader's."""
    ids = []
    for k in range(1, shards + 1):
        first, count = Shard(k, shards).robots(total)
        for w_first, w_count in split(count, min(workers, count)):
            names = [robot_name(first + w_first + i) for i in range(w_count)]
            ids += [link_client_id(prefix, name) for name in names]
            ids.append(reader_client_id(prefix, names))
    return ids


@pytest.mark.parametrize(("total", "shards", "workers"), [
    (1, 1, 1), (50, 1, 1), (50, 1, 4), (2000, 7, 3), (2000, 1000, 1), (12000, 3, 8)])
@pytest.mark.parametrize("prefix", [DEFAULT_PREFIX, "bench-flat-1764661882123456789", "é" * 30])
def test_fleet_client_ids_fit_mqtt_311_and_never_clash(
    total: int, shards: int, workers: int, prefix: str,
) -> None:
    ids = _fleet_ids(total, shards, workers, prefix)
    too_long = [i for i in ids if not 1 <= len(i.encode()) <= MAX_CLIENT_ID_BYTES]
    assert too_long == [], too_long[:5]
    assert len(set(ids)) == len(ids)  # one per robot, one reader per worker process


def test_a_short_link_id_is_kept_as_it_was() -> None:
    """A session a broker holds under ``odocan-bridge-robot001`` is found again."""
    assert link_client_id(DEFAULT_PREFIX, "robot001") == "odocan-bridge-robot001"


def test_the_bridge_gives_its_links_and_its_one_reader_ids_that_fit() -> None:
    """The ids a ``Bridge`` uses: an operator's 64-character robot name and the fleet's names
    under the default prefix; one reader for all of them, the same for the same robots."""
    names = ["r" * 64, robot_name(0), robot_name(999)]
    buses = [can.Bus(interface="virtual", channel=f"ids-{n}") for n in names]
    try:
        endpoints = [RobotEndpoint(n, bus, Geometry.of(PMIR), counter_bits=PMIR.counter_bits)
                     for n, bus in zip(names, buses, strict=True)]
        config = BridgeConfig(broker=BrokerURL("127.0.0.1", 1))
        bridge, again = Bridge(endpoints, config=config), Bridge(endpoints, config=config)
        ids = [link.client_id for link in bridge.links] + [bridge.commands.client_id]
        assert [len(i.encode()) <= MAX_CLIENT_ID_BYTES for i in ids] == [True] * 4, ids
        assert len(set(ids)) == 4
        assert ids[1] == "odocan-bridge-robot001"
        assert again.commands.client_id == bridge.commands.client_id  # its session, found again
        alone = Bridge(endpoints[1:2], config=config)  # another worker: another reader
        assert alone.commands.client_id != bridge.commands.client_id
    finally:
        for bus in buses:
            bus.shutdown()
