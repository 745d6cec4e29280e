"""How the bridge publishes, paces commands and holds frames (``host.mqtt.bridge``'s config,
apart: the bridge module at its size limit)."""

from __future__ import annotations

from dataclasses import dataclass

from odocan.host.mqtt.broker import BrokerURL
from odocan.host.mqtt.clientids import DEFAULT_PREFIX
from odocan.host.mqtt.pacing import ACK_TIMEOUT_S, MAX_QUEUED, WINDOW_FRAMES


@dataclass(frozen=True)
class BridgeConfig:
    """How the bridge publishes (periods in seconds, rates in Hz)."""

    broker: BrokerURL
    publish_hz: float = 10.0
    status_period_s: float = 1.0
    rates_period_s: float = 1.0
    keepalive_s: int = 5
    client_prefix: str = DEFAULT_PREFIX
    queue_batches: int = 1024
    slice_frames: int = 64  # frames judged in one go before the event loop gets a turn
    slice_step: int = 8  # frames the bridge takes at a time, counting those judged (a hold's)
    connect_timeout_s: float = 5.0  # the first connection, else BrokerError
    command_expiry_s: float = 5.0  # a command without its own MQTT v5 expiry, at most this old
    telemetry_buffer: int = 1000  # QoS-0 publications per robot waiting for the socket
    reliable_buffer: int = 1000  # QoS-1 publications per robot waiting for their PUBACK
    # command pacing per robot (``host.mqtt.pacing``): frames un-answered on the bus, the
    # ODOM_ACK's deadline after a command's last frame, commands waiting beyond the window
    command_window_frames: int = WINDOW_FRAMES
    command_ack_timeout_s: float = ACK_TIMEOUT_S
    command_queue: int = MAX_QUEUED
    pace_period_s: float = 0.05  # timeouts and expiries of paced commands checked this often
    hold_s: float = 0.0  # each robot's frames held up to this long for its judge (framehold)
