"""On-board vs truth over a life given chunk by chunk (issue #14.1): ``compare.versus_truth``
(``compare.onboard_at``: the on-board pose at a truth sample's encoder frame is the next
on-board sample's carried back along the placed reference), its summary bit for bit.

A truth sample waits for the first on-board sample at or after its encoder frame; on-board
samples are kept while a truth sample to come may need them (from ``TruthChunk.floor`` on).
Both arrive in encoder order, so the truth samples are compared in the whole log's order.
In a life after a reboot (``rebase``) the truth is re-based at the life's first truth sample
(``compare.life_origin``, as ``compare.rebased_at_start``)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from odocan.host.judge.compare import (
    carried,
    error_summary,
    life_origin,
    origin_dict,
    rebase_truth,
)
from odocan.host.judge.samples import HEADING_LSB_RAD, FloatArray, wrap_pi
from odocan.host.judge.stream_life import TruthChunk
from odocan.host.judge.stream_place import PlacedChunk

Placed = dict[str, np.ndarray]


@dataclass
class TruthCompare:
    """``versus_truth``'s summary for the reference placed at ``start`` (x0, y0, h0) with the
    segment ``offsets`` (x, y) (``stream_place``)."""

    start: tuple[float, float, float]
    offsets: tuple[FloatArray, FloatArray]
    rebase: bool = False  # a life after a reboot: the truth in its frame
    e0: int = 0  # the encoder frame the reference starts at
    origin: dict[str, Any] | None = None  # the truth's origin once re-based (``origin_dict``)
    compared: int = 0
    _onboard: Placed = field(default_factory=dict)  # enc, x, y, heading (raw), ref x, y, h
    _waiting: Placed = field(default_factory=dict)  # enc, truth x, y, h, ref x, y, h
    _top: tuple[float, float, float] = (-math.inf, -math.inf, 0.0)  # max pos, max |h|
    _last: tuple[FloatArray, FloatArray] | None = None

    def _reference(self, rel_x: FloatArray, rel_y: FloatArray, rel_h: FloatArray,
                   segment: np.ndarray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``build_reference``'s pose at encoder frames with these increments and segments."""
        x0, y0, h0 = self.start
        cos0, sin0 = math.cos(h0), math.sin(h0)
        x = x0 + cos0 * rel_x - sin0 * rel_y
        x += self.offsets[0][segment]
        y = y0 + sin0 * rel_x + cos0 * rel_y
        y += self.offsets[1][segment]
        return x, y, h0 + rel_h

    def feed(self, placed: PlacedChunk, truth: TruthChunk) -> None:
        """Take the next on-board and truth samples."""
        ref_x, ref_y, ref_h = self._reference(placed.rel_x_m, placed.rel_y_m,
                                              placed.rel_heading_rad, placed.segment)
        self._onboard = _cat(self._onboard, {
            "enc": placed.enc, "x": placed.x_m, "y": placed.y_m, "raw": placed.heading_raw,
            "rx": ref_x, "ry": ref_y, "rh": ref_h})
        here = self._reference(truth.rel_x_m, truth.rel_y_m, truth.rel_heading_rad,
                               truth.segment)
        tx, ty, th = truth.x_m, truth.y_m, truth.heading_rad
        if self.rebase and len(truth.enc):
            if self.origin is None:
                origin = life_origin((float(tx[0]), float(ty[0]), float(th[0])),
                                     (float(here[0][0]), float(here[1][0]), float(here[2][0])))
                self.origin = origin_dict(origin, int(truth.enc[0]), self.e0)
            at = self.origin
            tx, ty, th = rebase_truth(tx, ty, th, (at["x_m"], at["y_m"], at["heading_rad"]))
        self._waiting = _cat(self._waiting, {
            "enc": truth.enc, "x": tx, "y": ty, "h": th,
            "rx": here[0], "ry": here[1], "rh": here[2]})
        self._resolve()
        if self._onboard and truth.floor != math.inf:
            keep = self._onboard["enc"] >= truth.floor
            if len(keep) and not keep[-1]:
                keep[-1] = True  # the last is the next one for a truth sample at or below it
            self._onboard = {k: v[keep] for k, v in self._onboard.items()}

    def _resolve(self) -> None:
        w, o = self._waiting, self._onboard
        if not w or not o or len(w["enc"]) == 0 or len(o["enc"]) == 0:
            return
        following = np.searchsorted(o["enc"], w["enc"])
        ready = following < len(o["enc"])
        if not ready.any():
            return
        s = following[ready]
        t = {k: v[ready] for k, v in w.items()}
        heading = o["raw"][s] * HEADING_LSB_RAD
        est_x, est_y, est_h = carried((o["x"][s], o["y"][s], heading),
                                      (o["rx"][s], o["ry"][s], o["rh"][s]),
                                      (t["rx"], t["ry"], t["rh"]))
        est_h = np.asarray(est_h, dtype=np.float64)
        position = np.hypot(est_x - t["x"], est_y - t["y"])
        wrapped = wrap_pi(est_h - t["h"])
        self.compared += len(position)
        self._top = (max(self._top[0], float(np.max(position))),
                     max(self._top[1], float(np.max(np.abs(wrapped)))), 0.0)
        self._last = (position[-1:], wrapped[-1:])
        self._waiting = {k: v[~ready] for k, v in w.items()}

    def summary(self) -> dict[str, Any]:
        """``error_summary`` of the compared truth samples (without the distance)."""
        if self._last is None:
            return error_summary(np.zeros(0), np.zeros(0))
        result = error_summary(*self._last)
        result["max_position_error_m"] = self._top[0]
        result["max_heading_error_rad"] = self._top[1]
        return result


def _cat(a: Placed, b: Placed) -> Placed:
    if not a:
        return dict(b)
    return {k: np.concatenate((a[k], b[k])) for k in a}
