"""What one of the bridge's own answers costs the command reader when it comes back (#13).

The links publish each command's answer on ``odocan/<robot>/cmd/result``; the reader subscribes
``odocan/<robot>/cmd/+`` (an unknown command must be read to be answered), so every answer comes
back to it once (MQTT 3.1.1 has no no-local; v5's keeps only a connection's own). Here ``--echoes``
such messages, as paho hands them over, go through the reader's ``on_message`` (no broker, no
socket: paho's own packet parsing and PUBACK are not counted), and the process's CPU is printed.
Deterministic: under ``valgrind --tool=callgrind`` (``PYTHONHASHSEED=0``), the instructions of a
run with ``--echoes N`` less one with ``--echoes 0``, over N, are the cost of one echo, whatever
the load; compare trees that way:

    PYTHONHASHSEED=0 PYTHONPATH=<tree> valgrind --tool=callgrind .venv/bin/python \
        bench/reader_echoes.py --echoes 20000
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import paho.mqtt.client as paho

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from odocan.host.mqtt import cmdreader, topics
from odocan.host.mqtt.broker import BrokerURL


class _Client:
    """What the reader's ``on_message`` reads of its client: the reader (``sink`` in the trees
    before ``CommandReader.read``)."""

    reader: Any = None
    sink: Any = None


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--echoes", type=int, default=20000)
    args = parser.parse_args()
    reader = cmdreader.CommandReader(
        robots=["robot001"], broker=BrokerURL("127.0.0.1", 1), client_id="benchechoes",
        keepalive_s=5, connect_timeout_s=1.0, session_expiry_s=5.0, capacity=1000)
    client = _Client()
    client.reader = reader
    client.sink = getattr(reader, "_arrive", None)
    message = paho.MQTTMessage(mid=1, topic=topics.topic("robot001", topics.RESULT_LEAF).encode())
    message.payload = b'{"id":"x","command":"teleport","result":"rejected","reason":"unknown"}'
    message.qos = 1
    on_message = cmdreader._ReaderClient._on_message  # the reader's paho callback
    start_s = time.process_time()
    for _ in range(args.echoes):
        on_message(client, None, None, message)  # type: ignore[arg-type]
    spent_s = time.process_time() - start_s
    print(f"{args.echoes} echoes: {spent_s / max(args.echoes, 1) * 1e6:.2f} us CPU each, "
          f"queued {len(reader.robots['robot001'].arrived)}, "
          f"counted {getattr(reader, 'echoes', '-')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
