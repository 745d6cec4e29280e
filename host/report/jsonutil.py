"""JSON of reports, snapshots and MQTT payloads: ``odocan.host.jsonutil``, re-exported.

The module moved to host/ level so that io/ and judge/, below report/, can write JSON without an
arrow pointing back up; report/, cli/, mqtt/ and the other rooms above may go on importing it
from here (the same functions).
"""

from __future__ import annotations

from odocan.host.jsonutil import finite, json_default, real, report_json, write_report

__all__ = ["finite", "json_default", "real", "report_json", "write_report"]
