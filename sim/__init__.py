"""odocan sim: the hardware around the firmware (motors, encoders, ground truth, clocks, buses)."""

from importlib import resources
from pathlib import Path

# odocan's own DBC, package data (an installed wheel unpacks it to files): the process's DBC
# unless ODOCAN_DBC names another (``sim.contract.DBC_PATH``, read when that module is imported)
SHIPPED_DBC = Path(str(resources.files("odocan").joinpath("dbc", "odocan.dbc")))
