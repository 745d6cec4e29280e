"""MQTT side of odocan: telemetry out, validated commands in (aiomqtt on a real broker).

* ``topics``: the topic map, QoS classes and JSON payload helpers;
* ``broker``: ``--broker`` URLs (``mqtt://user:pass@host:port``, ``mqtts://`` + TLS files) and
  the embedded amqtt broker on a free loopback port;
* ``telemetry``: one robot's frames -> pose, reference, truth, error, status, rates;
* ``commands``: ``cmd/*`` JSON -> E2E-protected frames, validated against the DBC first;
* ``link``: one robot's MQTT connection (last will, persistent session, reconnect, buffer);
* ``bridge``: CAN <-> MQTT for any number of robots;
* ``fleetview``: a subscriber yielding per-robot state (the data source of a fleet table).
"""
