"""Two rigs on one machine on two udp_multicast groups must not hear each other.

python-can's udp_multicast binds ``0.0.0.0:PORT`` whatever the group, so on its default port
every group receives every other group's datagrams. odocan's bus opener derives the port from
the group (``host.io.buses.udp_port_for_group``). Here two sender/receiver pairs, opened as the
CLI opens them, run at once on two groups: each receiver gets exactly its own group's frames.
The control opens the same two pairs on python-can's shared default port and sees the
cross-talk the derivation removes (so the first test can fail).
"""

from __future__ import annotations

import argparse
import secrets
import time

import can
import pytest

from odocan.host.io.buses import isolated_bus_kwargs, open_bus, udp_port_for_group

FRAMES = 200
SETTLE_S = 0.5


def _groups() -> tuple[str, str]:
    """Two distinct random groups in the organisation-local scope, on distinct derived ports."""
    while True:
        a, b = (f"239.255.{secrets.randbelow(250) + 1}.{secrets.randbelow(250) + 1}"
                for _ in range(2))
        if a != b and udp_port_for_group(a) != udp_port_for_group(b):
            return a, b


def _args(group: str, *extra: str) -> argparse.Namespace:
    return argparse.Namespace(interface="udp_multicast", channel=group, bitrate=None,
                              bus_arg=["hop_limit=0", *extra], faults="")


def _open(group: str, *extra: str) -> can.BusABC:
    try:
        return open_bus(_args(group, *extra))
    except Exception as exc:  # no multicast route in this sandbox
        pytest.skip(f"udp_multicast unavailable: {exc}")


def _exchange(extra: tuple[str, ...]) -> dict[str, list[int]]:
    """Both groups send FRAMES frames tagged with their index at once; what each receiver got
    (the tag of every frame)."""
    groups = _groups()
    receivers = [_open(g, *extra) for g in groups]
    senders = [_open(g, *extra) for g in groups]
    try:
        for n in range(FRAMES):
            for tag, sender in enumerate(senders):
                sender.send(can.Message(arbitration_id=0x100 + tag, data=n.to_bytes(2, "little"),
                                        is_extended_id=False, is_fd=False))
            time.sleep(0.001)
        heard: dict[str, list[int]] = {}
        for group, receiver in zip(groups, receivers, strict=True):
            tags = []
            deadline = time.monotonic() + SETTLE_S
            while (msg := receiver.recv(max(0.0, deadline - time.monotonic()))) is not None:
                tags.append(msg.arbitration_id - 0x100)
            heard[group] = tags
        return heard
    finally:
        for bus in receivers + senders:
            bus.shutdown()


def test_two_groups_do_not_hear_each_other() -> None:
    heard = _exchange(())
    for tag, (group, tags) in enumerate(heard.items()):
        assert tags.count(1 - tag) == 0, f"{group} heard the other group's frames"
        assert tags.count(tag) == FRAMES, f"{group} lost its own frames"


def test_control_one_shared_port_is_cross_talk() -> None:
    heard = _exchange(("port=43113",))
    for tag, tags in enumerate(heard.values()):
        assert tags.count(tag) > 0
        assert tags.count(1 - tag) > 0  # what the README's shared-machine run suffered


def test_the_port_is_derived_only_for_udp_multicast_without_one() -> None:
    group = "239.74.163.9"
    port = udp_port_for_group(group)
    assert 20000 <= port < 30000
    assert port == udp_port_for_group(" 239.74.163.9 ")  # the same group, the same port
    assert udp_port_for_group("239.74.163.2") != port
    assert isolated_bus_kwargs({"interface": "udp_multicast", "channel": group}) == {
        "interface": "udp_multicast", "channel": group, "port": port}
    given = {"interface": "udp_multicast", "channel": group, "port": 43113}
    assert isolated_bus_kwargs(given) == given
    assert isolated_bus_kwargs({"interface": "virtual", "channel": "x"}) == {
        "interface": "virtual", "channel": "x"}
