"""Output paths checked before the work starts: ``odocan.host.outputs``, re-exported.

The module moved to host/ level so that io/ and judge/, below report/, can use ``OutputError``
without an arrow pointing back up; report/, cli/ and the other rooms above may go on importing it
from here. The names are the same objects (``except OutputError`` catches either spelling).
"""

from __future__ import annotations

from odocan.host.outputs import OutputError, check_writable, write_text

__all__ = ["OutputError", "check_writable", "write_text"]
