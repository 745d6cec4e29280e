"""The streamed judge's spill: the log's frames written once, column by column, and read back
by ranges (``stream_analysis.analyze_file``: each life's passes read its own frames)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

import numpy as np

from odocan.host.io.logs import FrameArrays


class FrameSpill:
    """The log's frames written once, column by column, to files in ``directory`` (26 bytes a
    frame, no text to parse again), then read back by ranges: each life's passes read its
    own frames, not the log from its start."""

    COLUMNS = (("timestamp_s", np.float64, ()), ("can_id", np.uint32, ()),
               ("dlc", np.uint8, ()), ("data", np.uint8, (8,)), ("flags", np.uint8, ()))

    def __init__(self, directory: Path) -> None:
        self._paths = {name: directory / f"{name}.bin" for name, _, _ in self.COLUMNS}
        self._files: dict[str, BinaryIO] = {
            name: path.open("wb") for name, path in self._paths.items()}

    def write(self, chunk: FrameArrays) -> None:
        for name, dtype, _ in self.COLUMNS:
            np.ascontiguousarray(getattr(chunk, name), dtype=dtype).tofile(self._files[name])

    def close(self) -> None:
        for file in self._files.values():
            file.close()

    def read(self, start: int, stop: int, chunk_frames: int) -> Iterator[FrameArrays]:
        """The frames [start, stop), ``chunk_frames`` at a time."""
        for lo in range(start, stop, chunk_frames):
            n = min(chunk_frames, stop - lo)
            columns = {}
            for name, dtype, shape in self.COLUMNS:
                width = int(np.prod(shape, dtype=np.int64))
                values = np.fromfile(self._paths[name], dtype=dtype, count=n * width,
                                     offset=lo * width * np.dtype(dtype).itemsize)
                columns[name] = values.reshape((n, *shape))
            yield FrameArrays(**columns)
