"""Every MQTT client id the bridge and the fleet use is 1-23 characters of 0-9a-zA-Z (MQTT
3.1.1's guarantee), and unique per robot, per shard and per worker process (#13).

MQTT 3.1.1 obliges a broker to accept client ids of 1-23 bytes of 0-9a-zA-Z only; the ids were
``odocan-bridge-<robot>`` (a dash: the default prefix's), the command readers' were
``<prefix>-<robot>-cmd`` (``odocan-bridge-robot001-cmd``: 26), a robot named by its
operator may take 64 characters, and the benches' prefixes carry a nanosecond clock. Checked
here against the shipped formats: the default prefix, the fleet's robot names
(``sim.fleet.robot_name``) of fleets split by ``--shard K/N`` and over ``--workers`` as
``host.mqtt.shards`` splits them (one bridge, so one command reader, per worker process), and
the ids a ``Bridge`` gives its links and its reader.
"""

from __future__ import annotations

import argparse
import re

import can
import pytest

from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.bridge import Bridge, BridgeConfig, RobotEndpoint
from odocan.host.mqtt.broker import BrokerURL
from odocan.host.mqtt.clientids import (
    MAX_CLIENT_ID_BYTES,
    link_client_id,
    reader_client_id,
)
from odocan.host.mqtt.options import add_mqtt_arguments
from odocan.host.mqtt.shards import Shard, split
from odocan.sim import robot
from odocan.sim.fleet import robot_name

DEFAULT_PREFIX = "odocanbridge"  # ``--client-prefix``'s default
MQTT_311_ID = re.compile(r"[0-9a-zA-Z]{1,23}")  # 3.1.3.1: what every server must accept
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
@pytest.mark.parametrize("prefix", [DEFAULT_PREFIX, "bench-flat-1764661882123456789", "é" * 30,
                                    "my-bridge", "a", ""])
def test_fleet_client_ids_fit_mqtt_311_and_never_clash(
    total: int, shards: int, workers: int, prefix: str,
) -> None:
    ids = _fleet_ids(total, shards, workers, prefix)
    refused = [i for i in ids if not MQTT_311_ID.fullmatch(i)]
    assert refused == [], refused[:5]
    assert len(set(ids)) == len(ids)  # one per robot, one reader per worker process


def test_the_default_prefix_is_the_options_and_its_ids_read_the_robot() -> None:
    """``--client-prefix``'s default conforms; a fleet robot's id is prefix and name joined,
    readable in the broker's log, and the same from run to run (its session found again)."""
    parser = argparse.ArgumentParser()
    add_mqtt_arguments(parser)
    assert parser.parse_args([]).client_prefix == DEFAULT_PREFIX
    assert link_client_id(DEFAULT_PREFIX, "robot001") == "odocanbridgerobot001"
    assert link_client_id("my-bridge", "robot001") == link_client_id("my-bridge", "robot001")


@pytest.mark.parametrize(("prefix", "robots"), [
    ("odocanbridge", ["robot-1", "robot1", "robot_1", "robot.1", "r" * 64, "r" * 63]),
    ("", ["a", "b", "a-", "-a"]),
    ("my-bridge", ["robot001", "robot002"]),
    ("mybridge", ["robot001", "robot002"]),
])
def test_names_that_differ_only_by_other_characters_keep_distinct_ids(
    prefix: str, robots: list[str],
) -> None:
    """Letters and digits are all an id may hold, so a name's other characters go: names that
    differ only by them (``robot-1``, ``robot1``, ``robot_1``) and the same robots under
    ``my-bridge`` and ``mybridge`` still get ids of their own, each conforming."""
    ids = [link_client_id(prefix, r) for r in robots]
    ids += [reader_client_id(prefix, robots), reader_client_id(prefix, robots[:1])]
    other = [link_client_id("mybridge" if prefix == "my-bridge" else "my-bridge", r)
             for r in robots]
    assert all(MQTT_311_ID.fullmatch(i) for i in ids + other), ids + other
    assert len(set(ids + other)) == len(ids + other)


def test_a_reader_never_takes_a_links_id() -> None:
    """The reader of robot ``robot001`` and the link of a robot named ``cmdrobot001`` (or
    ``-cmd-robot001``'s letters) under one prefix: two connections, two ids."""
    links = [link_client_id(DEFAULT_PREFIX, r) for r in ("cmdrobot001", "cmd-robot001")]
    assert reader_client_id(DEFAULT_PREFIX, ["robot001"]) not in links


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
        assert [bool(MQTT_311_ID.fullmatch(i)) for i in ids] == [True] * 4, ids
        assert max(len(i.encode()) for i in ids) <= MAX_CLIENT_ID_BYTES
        assert len(set(ids)) == 4
        assert ids[1] == "odocanbridgerobot001"
        assert again.commands.client_id == bridge.commands.client_id  # its session, found again
        alone = Bridge(endpoints[1:2], config=config)  # another worker: another reader
        assert alone.commands.client_id != bridge.commands.client_id
    finally:
        for bus in buses:
            bus.shutdown()
