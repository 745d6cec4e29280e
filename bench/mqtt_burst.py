"""CPU of one robot's telemetry burst handed to paho and written: per message, or as one batch.

A fleet worker's link hands paho a robot's telemetry of one period (pose, reference, error and
truth: four QoS-0 publications, ``host.mqtt.link.RobotLink._send_telemetry``) and writes it at
once. Per message, paho's ``publish`` checks the topic, builds the packet, makes an
``MQTTMessageInfo`` (a ``Condition`` and its lock) and a queue entry, and its write loop does
its bookkeeping per packet; ``LinkClient.publish_batch`` builds the packets back to back
(``host.mqtt.client.publish_packets``) as one queue entry with one info. Both are timed here
(process time, rounds alternating) against a socket that takes every byte at once, so only the
Python side counts, not the syscall nor the broker:

    .venv/bin/python bench/mqtt_burst.py [--bursts 20000] [--rounds 3]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import paho.mqtt.client as paho
from paho.mqtt.enums import CallbackAPIVersion

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from odocan.host.mqtt.client import publish_packets

LEAVES = ("pose", "reference", "error", "truth")


class _Socket:
    def send(self, buf: bytes) -> int:
        return len(buf)

    def fileno(self) -> int:
        return -1

    def close(self) -> None:
        pass


def _client() -> paho.Client:
    mqtt = paho.Client(CallbackAPIVersion.VERSION2, protocol=paho.MQTTv5)
    mqtt._sock = _Socket()  # type: ignore[assignment]
    mqtt.on_socket_register_write = lambda *_: None  # written by loop_write below, as the link
    return mqtt


def burst() -> list[tuple[str, bytes]]:
    """Four telemetry messages of a pose's usual size."""
    payload = {"t_s": 12.34, "counter": 7, "enc_counter": 1234, "enc_seq": 1234,
               "x_m": 1.2345678901234, "y_m": -0.98765432109876, "heading_rad": 1.2345678,
               "heading_unwrapped_rad": 7.5177531, "linear_vel_m_s": 0.4321,
               "angular_vel_rad_s": -0.1234, "distance_m": 12.345, "unix_s": 1764600000.123456}
    body = json.dumps(payload, separators=(",", ":")).encode()
    return [(f"odocan/robot001/{leaf}", body) for leaf in LEAVES]


def per_message_us(bursts: int) -> float:
    mqtt, messages = _client(), burst()
    t0_s = time.process_time()
    for _ in range(bursts):
        for topic, body in messages:
            mqtt.publish(topic, body, 0)
        mqtt.loop_write()
    return (time.process_time() - t0_s) / bursts * 1e6


def batched_us(bursts: int) -> float:
    mqtt, messages = _client(), burst()
    prefixes: dict[str, bytes] = {}
    t0_s = time.process_time()
    for _ in range(bursts):  # LinkClient.publish_batch, then its flush
        packet = publish_packets(messages, v5=True, prefixes=prefixes)
        info = paho.MQTTMessageInfo(mqtt._mid_generate())
        mqtt._packet_queue(paho.PUBLISH, packet, info.mid, 0, info)
        mqtt.loop_write()
    return (time.process_time() - t0_s) / bursts * 1e6


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bursts", type=int, default=20000)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    for _ in range(args.rounds):
        one, many = per_message_us(args.bursts), batched_us(args.bursts)
        print(f"burst of {len(LEAVES)}: paho per message {one:.1f} us, one batch {many:.1f} us "
              f"of CPU", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
