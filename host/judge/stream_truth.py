"""SIM_TRUTH's samples chunk by chunk (issue #14.1): ``host.judge.samples.truth_samples`` over
a log fed in chunks, sample for sample the whole log's.

A truth sample is SIM_TRUTH's three parts (X, Y, HEADING, pages 0 to 2) naming one encoder
frame, the first of each. It is aligned like an on-board sample, so ``StreamTruth`` is
``host.judge.stream.StreamPoses`` with three kinds of frames instead of two: a part naming an
encoder frame the log has not reached waits for it (and the parts of its page after it), a
sample leaves once no later frame can name its encoder frame, parts without their partners
are dropped."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M
from odocan.host.judge.stream import StreamPoses
from odocan.host.protocol.decode import DecodeError

PARTS = {"SIM_TRUTH/0": (0, "X"), "SIM_TRUTH/1": (1, "Y"), "SIM_TRUTH/2": (2, "HEADING")}


def _no_parts() -> dict[str, dict[int, tuple[int, dict[str, float], float]]]:
    return {name: {} for name in PARTS}


@dataclass
class StreamTruth(StreamPoses):
    """The truth samples of ``samples.truth_samples``, chunk by chunk (module docstring);
    ``feed`` and ``finish`` give columns enc, x_m, y_m, heading_rad, heading_raw (and the send
    times of the HEADING parts, unused)."""

    _first: dict[str, dict[int, tuple[int, dict[str, float], float]]] = field(
        default_factory=_no_parts)
    causal: bool = False  # the simulator names its own sample (``samples.truth_samples``)

    def _rows(self, chunk: FrameArrays, name: str) -> dict[str, np.ndarray]:
        """One part's frames: index, timestamp_s, ENC_COUNTER and its value (none without
        SIM_TRUTH in the DBC)."""
        page, signal = PARTS[name]
        try:
            rows = self.decoder.decode_page(chunk, "SIM_TRUTH", page)
        except (DecodeError, KeyError):
            empty = np.zeros(0, dtype=np.int64)
            return {"index": empty, "timestamp_s": np.zeros(0), "ENC_COUNTER": empty,
                    signal: empty}
        return {k: rows[k] for k in ("index", "timestamp_s", "ENC_COUNTER", signal)}

    def _emit(self, floor: float) -> tuple[dict[str, np.ndarray], npt.NDArray[np.float64]]:
        """The truth samples of encoder frames below sequence ``floor``, in encoder order."""
        parts = [self._first[name] for name in PARTS]
        done = sorted(g for g in set().union(*parts)
                      if next(p[g][0] for p in parts if g in p) < floor)
        common = [g for g in done if all(g in p for p in parts)]
        values = [[p[g][1][signal] for g in common]
                  for p, (_, signal) in zip(parts, PARTS.values(), strict=True)]
        sent = np.array([parts[2][g][2] for g in common], dtype=np.float64)
        for g in done:
            for p in parts:
                p.pop(g, None)
        heading_raw = np.array(values[2], dtype=np.int64)
        samples = {
            "enc": np.array(common, dtype=np.int64),
            "x_m": np.array(values[0]) * POSITION_LSB_M,
            "y_m": np.array(values[1]) * POSITION_LSB_M,
            "heading_rad": heading_raw.astype(np.float64) * HEADING_LSB_RAD,
            "heading_raw": heading_raw,
        }
        return samples, sent
