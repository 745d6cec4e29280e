"""Parquet tables of an analysed drive (pyarrow), for DuckDB, pandas, polars.

``write_parquet(DIR, frames, analysis)`` writes one table per DBC message heard, with its decoded
signals scaled to physical values (``X_m``, ``LEFT_COUNT_count``, ``LEFT_SPEED_m_per_s``; signals
of unit ``-`` keep their bare name; a multiplexed signal is null where its page is not selected),
``timestamp_s``, ``index`` (the frame's position in the log) and ``e2e_ok``; ``frames.parquet``
with every raw frame; ``series.parquet`` with the analysis per on-board sample (``timestamp_s``,
``onboard_x_m`` ... ``reference_heading_rad``, ``distance_m``, ``position_error_m``,
``heading_error_rad``) and ``truth.parquet`` per compared truth sample (``truth_x_m`` ...,
``truth_position_error_m``: on-board minus truth). The JSON report rides along in the schema
metadata of ``series.parquet`` (key ``odocan.report``).
"""

from __future__ import annotations

from pathlib import Path

import cantools
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from cantools.database.can import Message, Signal

from odocan.host.io.export import column_name
from odocan.host.io.logs import FLAG_ERROR, FLAG_EXTENDED, FLAG_REMOTE, FrameArrays
from odocan.host.jsonutil import report_json
from odocan.host.judge.analysis import Analysis
from odocan.host.outputs import replaced_together
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import check_frames
from odocan.sim import contract

REPORT_KEY = b"odocan.report"


# --- decoded signals -----------------------------------------------------------------------


def message_tables(
    frames: FrameArrays, db: cantools.database.can.Database | None = None
) -> dict[str, pa.Table]:
    """One Arrow table per DBC message with at least one frame in ``frames`` (module doc)."""
    db = db if db is not None else contract.database()
    decoder = BulkDecoder(db)
    _, accepted = check_frames(frames, db)
    tables = {}
    for message in db.messages:
        if message.length > 8:
            continue
        decoded = decoder.decode(frames, message.name)
        if len(decoded["index"]):
            tables[message.name] = _message_table(message, decoded, accepted[decoded["index"]])
    return tables


def _message_table(
    message: Message, decoded: dict[str, np.ndarray], e2e_ok: np.ndarray
) -> pa.Table:
    columns: dict[str, pa.Array] = {
        "timestamp_s": pa.array(decoded["timestamp_s"], pa.float64()),
        "index": pa.array(decoded["index"], pa.int64()),
        "e2e_ok": pa.array(e2e_ok, pa.bool_()),
    }
    for signal in message.signals:
        value = _physical(signal, decoded[signal.name])
        mask = None
        if signal.multiplexer_signal is not None:
            selector = decoded[signal.multiplexer_signal]
            mask = ~np.isin(selector, list(signal.multiplexer_ids or ()))
        columns[column_name(signal)] = pa.array(value, mask=mask)
    return pa.table(columns)


def _physical(signal: Signal, raw: np.ndarray) -> np.ndarray:
    """Raw values scaled (``raw * scale + offset``); integers stay int64 when scale is 1."""
    if not signal.is_float and signal.scale == 1 and signal.offset == 0:
        return raw.astype(np.int64)
    return raw.astype(np.float64) * float(signal.scale) + float(signal.offset)


def frames_table(frames: FrameArrays) -> pa.Table:
    """Every raw frame: ``timestamp_s``, ``can_id``, ``extended``, ``remote``, ``error``,
    ``dlc`` and ``data`` (the ``dlc`` payload bytes)."""
    data = [bytes(row[:dlc]) for row, dlc in zip(frames.data, frames.dlc, strict=True)]
    return pa.table({
        "timestamp_s": pa.array(frames.timestamp_s, pa.float64()),
        "can_id": pa.array(frames.can_id, pa.uint32()),
        "extended": pa.array((frames.flags & FLAG_EXTENDED) != 0),
        "remote": pa.array((frames.flags & FLAG_REMOTE) != 0),
        "error": pa.array((frames.flags & FLAG_ERROR) != 0),
        "dlc": pa.array(frames.dlc, pa.uint8()),
        "data": pa.array(data, pa.binary()),
    })


# --- the analysis series -------------------------------------------------------------------


EVENT_PREFIXES = ("gap_", "restart_")  # spans and instants, not per-sample columns


def series_tables(analysis: Analysis) -> tuple[pa.Table, pa.Table, pa.Table]:
    """(per on-board sample, per compared truth sample, gaps and reference restarts) tables of
    ``analysis.series``: each column goes to the table whose rows it has; a series of another
    length (e.g. the sim's full-rate truth, ``truth_full_*``, kept for the plots) is not a
    column of these."""
    series = analysis.series
    events = {k: v for k, v in series.items() if k.startswith(EVENT_PREFIXES)}
    n_onboard = len(series["onboard_x_m"])
    n_truth = len(series["truth_timestamp_s"])
    truth = {k: v for k, v in series.items()
             if k.startswith("truth_") and k not in events and len(v) == n_truth}
    onboard = {k: v for k, v in series.items()
               if k not in truth and k not in events and not k.startswith("truth_")
               and len(v) == n_onboard}
    truth_columns = {"timestamp_s": truth.pop("truth_timestamp_s"), **truth}
    return _table(onboard), _table(truth_columns), _events_table(events)


def _events_table(events: dict[str, np.ndarray]) -> pa.Table:
    """One row per gap (``kind`` gap: start and end) or reference restart (start = end)."""
    rows: dict[str, list[object]] = {"kind": [], "start_t_s": [], "end_t_s": [],
                                     "start_distance_m": [], "end_distance_m": []}
    spans = (("gap", "gap_start_", "gap_end_"), ("restart", "restart_", "restart_"))
    for kind, start, end in spans:
        if f"{start}t_s" not in events:
            continue
        rows["kind"] += [kind] * len(events[f"{start}t_s"])
        for field, prefix in (("start", start), ("end", end)):
            rows[f"{field}_t_s"] += np.asarray(events[f"{prefix}t_s"], dtype=float).tolist()
            rows[f"{field}_distance_m"] += np.asarray(
                events[f"{prefix}distance_m"], dtype=float).tolist()
    return pa.table(rows)


def _table(columns: dict[str, np.ndarray]) -> pa.Table:
    return pa.table({name: pa.array(np.asarray(v)) for name, v in columns.items()})


def write_parquet(
    directory: Path,
    frames: FrameArrays,
    analysis: Analysis,
    db: cantools.database.can.Database | None = None,
) -> list[Path]:
    """Write the tables of the module docstring into ``directory`` (made if missing), all or
    none (``replaced_together``: a full disk leaves no partial file, an older set as it was);
    returns the files written."""
    directory.mkdir(exist_ok=True)
    series, truth, events = series_tables(analysis)
    report = report_json(analysis.report).encode()
    series = series.replace_schema_metadata({REPORT_KEY: report})
    tables = {**message_tables(frames, db), "frames": frames_table(frames),
              "series": series, "truth": truth, "events": events}
    written = [directory / f"{name}.parquet" for name in tables]
    with replaced_together(written, "--parquet", directory) as temps:
        for table, temp in zip(tables.values(), temps, strict=True):
            pq.write_table(table, temp)
    return written

