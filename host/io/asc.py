"""An ``.asc`` log's lines for python-can's ``ASCReader``, its garbage lines left out and counted.

python-can's reader skips any line it does not recognise without a word (``garbage !!``), and
stops the whole read at a frame line it cannot parse (``0.5 1 1X0 Rx d 8 zz``: an ID or a data
byte that is not a number), so one bad line lost the whole log. ``AscLines`` hands the reader
every line but those two kinds -- a frame line that would not parse, and a line that is neither
a timestamped event, a header or footer line, nor a comment -- and counts them, as the cut last
line of a candump log is counted (``host.io.logs``): the caller warns with the count and the
first one's line number.

python-can reads every timestamp as absolute; a log written with ``timestamps relative``
(CANalyzer's option: each event's time after the previous event's) came out as a jumble of
deltas, times going back, no pose pairing the judge could use. ``AscLines`` hands such lines on
with their absolute time (the running sum, exact in decimal).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from decimal import Decimal
from typing import TextIO

_FRAME = re.compile(r"\s*\d+\.\d+\s+(\d+)\s+(\S+)\s+(Tx|Rx)\b(.*)$")
_FRAME_LIKE = re.compile(r"\s*\d+\.\d+\s+\d+\s+\w+\s+(Tx|Rx)\b")  # what python-can parses
_EVENT = re.compile(r"\s*\d+\.\d+\s")  # a timestamped line python-can reads or skips itself
_HEADER = re.compile(
    r"\s*(date\s|base\s|(no\s+)?internal\s+events|begin\s+triggerblock|end\s+triggerblock|//)",
    re.IGNORECASE)
_BASE = re.compile(r"\s*base\s+(hex|dec)\b(?:\s+timestamps\s+(\w+))?", re.IGNORECASE)
_STAMP = re.compile(r"(\s*)(\d+\.\d+)(\s.*)", re.DOTALL)
_DLC_BYTES = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)  # python-can's dlc2len


class AscLines:
    """An iterator over ``file``'s lines for ``can.ASCReader``: ``skipped`` lines left out,
    ``first_skipped`` the first one's line number (1-based; 0: none)."""

    def __init__(self, file: TextIO) -> None:
        self.file = file
        self.base = 16
        self.relative_s: Decimal | None = None  # the running time of a relative log
        self.line = 0
        self.skipped = 0
        self.first_skipped = 0
        self._lines: Iterator[str] = iter(file)

    def __iter__(self) -> AscLines:
        return self

    def __next__(self) -> str:
        for text in self._lines:
            self.line += 1
            if (base := _BASE.match(text)) is not None:
                self.base = 16 if base.group(1).lower() == "hex" else 10
                relative = (base.group(2) or "").lower() == "relative"
                self.relative_s = Decimal(0) if relative else None
            if _is_garbage(text, self.base):
                self.skipped += 1
                self.first_skipped = self.first_skipped or self.line
                continue
            return text if self.relative_s is None else self._absolute(text)
        raise StopIteration

    def _absolute(self, text: str) -> str:
        """A timestamped line of a relative log with its time made absolute."""
        stamp = _STAMP.match(text)
        if stamp is None or self.relative_s is None:
            return text
        self.relative_s += Decimal(stamp.group(2))
        return f"{stamp.group(1)}{self.relative_s:f}{stamp.group(3)}"

    def close(self) -> None:
        """Close the file (``ASCReader.stop``)."""
        self.file.close()


def _is_garbage(text: str, base: int) -> bool:
    """A line python-can would fail on, or skip although it is no ASC line at all (an event
    line without its newline is the file's last, cut by a killed recorder before it was whole:
    ``1.981000 1  ``)."""
    if not text.strip():
        return False
    if _FRAME_LIKE.match(text):
        return not _frame_parses(text, base)
    if not text.endswith("\n") and _EVENT.match(text):  # the last line, cut before its frame
        return True
    return not (_EVENT.match(text) or _HEADER.match(text))


def _frame_parses(text: str, base: int) -> bool:
    """Whether python-can's classic-frame parser takes this line (``ID Tx|Rx d DLC BYTES``,
    ``ID Tx|Rx r [DLC]``)."""
    match = _FRAME.match(text)
    if match is None:
        return False
    raw_id, rest = match.group(2), match.group(4).split()
    if not _number(raw_id[:-1] if raw_id[-1:].lower() == "x" else raw_id, base, 1 << 29):
        return False
    if not rest:
        return False
    if rest[0].lower().startswith("r"):
        return True
    if len(rest) < 2 or not _number(rest[1], base, len(_DLC_BYTES)):
        return False
    length = min(8, _DLC_BYTES[int(rest[1], base)])
    data = rest[2:2 + length]
    return all(_number(byte, base, 256) for byte in data)


def _number(text: str, base: int, below: int) -> bool:
    """``text`` is a whole number in ``base`` (digits only, as python-can reads them), under
    ``below``."""
    digits = "0123456789abcdef"[:base]
    return bool(text) and all(c in digits for c in text.lower()) and int(text, base) < below
