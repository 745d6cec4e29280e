"""An MCAP file of an analysed drive, for Foxglove.

Written with foxglove-sdk's MCAP writer (the Rust ``mcap`` crate behind one Python call per
message: about 10 us a message against about 60 us for the pure-Python ``mcap`` writer, which
made a 10-minute drive's 600 000 messages take 36 s); read back in the tests with the ``mcap``
library's reader. JSON messages with JSON schemas (Foxglove's well-known
``foxglove.PoseInFrame`` and ``foxglove.FrameTransform`` field names, see ``host.io.export``), so
any MCAP reader decodes it without generated code and Foxglove opens it as it is:

==================  ==========================  ================================================
topic               schema                      what
==================  ==========================  ================================================
/can/frames         odocan.CanFrame             every raw frame: id, flags, dlc, data bytes
/can/<MESSAGE>      odocan.<MESSAGE>            its decoded signals, named as in the Parquet
/pose/onboard       foxglove.PoseInFrame        the on-board pose decoded from the bus (odom)
/pose/reference     foxglove.PoseInFrame        the float64 reference at the same samples
/pose/truth         foxglove.PoseInFrame        the simulator's ground truth
/tf                 foxglove.FrameTransform     odom -> base_link (on-board),
                                                odom -> reference_link, odom -> truth_link
/errors/reference   odocan.PoseError            on-board minus reference (m, rad)
/errors/truth       odocan.PoseError            on-board minus truth (m, rad)
==================  ==========================  ================================================

Log times are the frames' timestamps in nanoseconds (simulated time for ``odocan run``); the JSON
report is the file's metadata record ``odocan.report`` (key ``json``).
"""

from __future__ import annotations

import heapq
import json
import logging
import re
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import cantools
import foxglove
import numpy as np
import pyarrow as pa
from cantools.database.can import Message

from odocan.host.io.export import (
    POSE_TOPICS,
    SCHEMAS,
    TIME_SCHEMA,
    can_frame,
    column_name,
    foxglove_time,
    frame_transform,
    json_schema,
    pose_error,
    pose_in_frame,
    to_ns,
)
from odocan.host.io.logs import FLAG_ERROR, FLAG_EXTENDED, FLAG_REMOTE, FrameArrays
from odocan.host.io.parquet import message_tables
from odocan.host.jsonutil import report_json
from odocan.host.judge.analysis import Analysis
from odocan.sim import contract

Record = tuple[int, str, dict[str, Any]]  # (log time ns, topic, JSON message)
CHUNK = 65536  # frames or rows turned into Python objects at a time



def write_mcap(
    path: Path,
    frames: FrameArrays,
    analysis: Analysis,
    db: cantools.database.can.Database | None = None,
) -> int:
    """Write the MCAP file of the module docstring; returns the number of messages."""
    db = db if db is not None else contract.database()
    schemas = {name: json_schema(name) for name in SCHEMAS}
    topics = {"/can/frames": "odocan.CanFrame", "/tf": "foxglove.FrameTransform",
              "/errors/reference": "odocan.PoseError", "/errors/truth": "odocan.PoseError"}
    topics.update({topic: "foxglove.PoseInFrame" for topic, _ in POSE_TOPICS.values()})
    tables = message_tables(frames, db)
    for name in tables:
        schema = message_schema(db.get_message_by_name(name))
        schemas[f"odocan.{name}"] = json.dumps(schema).encode()
        topics[f"/can/{name}"] = f"odocan.{name}"
    streams = [_frame_records(frames), *_signal_records(tables),
               *analysis_records(analysis.series)]
    records = heapq.merge(*streams, key=lambda record: record[0])  # each stream in time order
    context = foxglove.Context()
    count = 0
    with _sink_errors() as failed:
        try:
            with foxglove.open_mcap(path, allow_overwrite=True, context=context) as writer:
                channels = {
                    topic: foxglove.Channel(
                        topic, message_encoding="json", context=context,
                        schema=foxglove.Schema(name=name, encoding="jsonschema",
                                               data=schemas[name]),
                    )
                    for topic, name in topics.items()
                }
                writer.write_metadata("odocan.report", {"json": report_json(analysis.report)})
                for t_ns, topic, message in records:
                    channels[topic].log(json.dumps(message).encode(), log_time=t_ns)
                    count += 1
                    if failed:
                        break
        except RuntimeError:  # closing after a failed write fails again: the first cause counts
            if not failed:
                raise
    if failed:
        raise RuntimeError(failed[0])
    return count


class _SinkErrors(logging.Handler):
    """Takes the foxglove SDK's log records (its MCAP sink reports a failed write as a
    ``WARNING`` per message, "error logging message: McapError(Io(Os {... message: "No space
    left on device" }))", and goes on): the first one's reason is kept, none is printed."""

    def __init__(self, failed: list[str]) -> None:
        super().__init__(logging.WARNING)
        self.failed = failed

    def emit(self, record: logging.LogRecord) -> None:
        if not self.failed:
            text = record.getMessage()
            found = re.search(r'message: "([^"]*)"', text)
            self.failed.append(found.group(1) if found else text)


@contextmanager
def _sink_errors() -> Iterator[list[str]]:
    """While inside, the foxglove SDK's warnings go to a list (empty while all is well),
    not to stderr: a full disk is one error line, not one line per message."""
    failed: list[str] = []
    logger = logging.getLogger("foxglove")
    handler, propagate = _SinkErrors(failed), logger.propagate
    logger.addHandler(handler)
    logger.propagate = False
    try:
        yield failed
    finally:
        logger.removeHandler(handler)
        logger.propagate = propagate


def _frame_records(frames: FrameArrays) -> Iterator[Record]:
    """``/can/frames``, in bus order, converted ``CHUNK`` frames at a time."""
    for start in range(0, len(frames), CHUNK):
        part = frames.select(np.arange(start, min(start + CHUNK, len(frames))))
        for t_s, can_id, dlc, data, flags in zip(
            part.timestamp_s.tolist(), part.can_id.tolist(), part.dlc.tolist(),
            part.data.tolist(), part.flags.tolist(), strict=True,
        ):
            t_ns = to_ns(t_s)
            yield t_ns, "/can/frames", can_frame(
                t_ns, can_id, bytes(data[:dlc]), extended=bool(flags & FLAG_EXTENDED),
                remote=bool(flags & FLAG_REMOTE), error=bool(flags & FLAG_ERROR),
            )


def _signal_records(tables: dict[str, pa.Table]) -> list[Iterator[Record]]:
    """One ``/can/<MESSAGE>`` stream per message table."""
    return [_table_records(f"/can/{name}", table) for name, table in tables.items()]


def _table_records(topic: str, table: pa.Table) -> Iterator[Record]:
    signals = [c for c in table.column_names if c not in ("timestamp_s", "index", "e2e_ok")]
    for batch in table.select(["timestamp_s", *signals]).to_batches(max_chunksize=CHUNK):
        for row in batch.to_pylist():
            t_ns = to_ns(row.pop("timestamp_s"))
            values = {k: v for k, v in row.items() if v is not None}
            yield t_ns, topic, {"timestamp": foxglove_time(t_ns), **values}


def analysis_records(series: dict[str, np.ndarray]) -> list[Iterator[Record]]:
    """Poses, transforms and errors of ``Analysis.series``: one (log time, topic, message)
    stream per pose and per error series."""
    streams = [_pose_records(series, prefix) for prefix in POSE_TOPICS]
    streams.append(_error_records(series, "/errors/reference", "timestamp_s", ""))
    streams.append(_error_records(series, "/errors/truth", "truth_timestamp_s", "truth_"))
    return streams


def _pose_records(series: dict[str, np.ndarray], prefix: str) -> Iterator[Record]:
    topic, child = POSE_TOPICS[prefix]
    times = series["truth_timestamp_s" if prefix == "truth" else "timestamp_s"].tolist()
    xs, ys, hs = (series[f"{prefix}_{k}"].tolist() for k in ("x_m", "y_m", "heading_rad"))
    for t_s, x, y, h in zip(times, xs, ys, hs, strict=True):
        t_ns = to_ns(t_s)
        yield t_ns, topic, pose_in_frame(t_ns, x, y, h)
        yield t_ns, "/tf", frame_transform(t_ns, child, x, y, h)


def _error_records(
    series: dict[str, np.ndarray], topic: str, time_key: str, prefix: str
) -> Iterator[Record]:
    times = series[time_key].tolist()
    pos = series[f"{prefix}position_error_m"].tolist()
    head = series[f"{prefix}heading_error_rad"].tolist()
    for t_s, p, h in zip(times, pos, head, strict=True):
        t_ns = to_ns(t_s)
        yield t_ns, topic, pose_error(t_ns, p, h)


def message_schema(message: Message) -> dict[str, Any]:
    """A JSON schema of ``odocan.<MESSAGE>``: timestamp and its signals' columns."""
    props: dict[str, Any] = {"timestamp": TIME_SCHEMA}
    for signal in message.signals:
        integer = not signal.is_float and signal.scale == 1 and signal.offset == 0
        props[column_name(signal)] = {"type": "integer" if integer else "number"}
    return {"title": f"odocan.{message.name}", "type": "object", "properties": props}
