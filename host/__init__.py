"""odocan host: the tools a person runs (CLI, decoding, float64 reference, reports, MQTT).

``ODOCAN_ACCEL=1``: the bridge's per-frame path compiled with mypyc (``host.accel``), installed
here, before any host module loads, in every process (a fleet's spawned workers too)."""

import os as _os

if _os.environ.get("ODOCAN_ACCEL", "") not in ("", "0"):
    from odocan.host.accel import install as _install

    _install()
