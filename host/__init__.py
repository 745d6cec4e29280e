"""odocan host: the tools a person runs (CLI, decoding, float64 reference, reports, MQTT).

``ODOCAN_ACCEL=1``: the bridge's per-frame path compiled with mypyc (``host.accel``), installed
here, before any host module loads, in every process (a fleet's spawned workers too); ``0`` or
unset: pure Python. Any other value is a mistake said in one line, exit 2: a typo must not
silently run the slower path."""

import os as _os

_ACCEL = _os.environ.get("ODOCAN_ACCEL", "")
if _ACCEL not in ("", "0", "1"):
    import sys as _sys

    print(f"odocan: ODOCAN_ACCEL={_ACCEL!r}: must be 1 (the per-frame path compiled with mypyc) "
          "or 0 (pure Python)", file=_sys.stderr)
    raise SystemExit(2)
if _ACCEL == "1":
    from odocan.host.accel import install as _install

    _install()
