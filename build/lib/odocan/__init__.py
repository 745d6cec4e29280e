"""odocan: fixed-point odometry firmware simulated over CAN bus, and the host tools that judge it.

One import name, four rooms (the repository's top-level folders, linked here):

- ``odocan.firmware``: the MCU, integer-only and standard-library-only;
- ``odocan.sim``: the hardware around it (motors, encoders, truth, clocks, buses);
- ``odocan.host``: the tools a person runs (the ``odocan`` CLI, the judge, MQTT, the pytest kit);
- ``odocan.dbc``: the bus contract, ``odocan.dbc``, shipped as package data.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("odocan")
except PackageNotFoundError:  # a source checkout that was never installed
    __version__ = "0+unknown"
