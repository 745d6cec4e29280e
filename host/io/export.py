"""Exports of an analysed drive where robotics people look: the CLI's ``--parquet DIR`` and
``--mcap PATH`` (``host.io.parquet``, ``host.io.mcap``, imported only when asked for), and the
Foxglove messages the MCAP file and the live server (``host.report.foxglove``) share: JSON with
the field names of Foxglove's published schemas (``foxglove.PoseInFrame``,
``foxglove.FrameTransform``; a ``time`` is ``{"sec", "nsec"}``), in the frame ``odom``.
"""

from __future__ import annotations

import argparse
import json
import math
import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

from odocan.sim.exceptions import ConfigurationError

if TYPE_CHECKING:
    import cantools
    from cantools.database.can import Signal

    from odocan.host.io.logs import FrameArrays
    from odocan.host.judge.analysis import Analysis

ODOM_FRAME = "odom"
# (topic, child frame) of each pose in ``Analysis.series`` by its column prefix
POSE_TOPICS = {
    "onboard": ("/pose/onboard", "base_link"),
    "reference": ("/pose/reference", "reference_link"),
    "truth": ("/pose/truth", "truth_link"),
}


# --- the CLI's options -----------------------------------------------------------------------


def add_export_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--parquet DIR`` and ``--mcap PATH`` (``odocan run``, ``odocan analyze``)."""
    group = parser.add_argument_group("exports")
    group.add_argument(
        "--parquet", type=Path, metavar="DIR",
        help="write the decoded signals per message and the pose/reference/truth/error series "
        "as Parquet tables into DIR (made if missing)",
    )
    group.add_argument(
        "--mcap", type=Path, metavar="PATH",
        help="write the raw frames, decoded signals, poses, transforms and errors as an MCAP "
        "file for Foxglove",
    )


def write_exports(
    args: argparse.Namespace,
    frames: FrameArrays,
    analysis: Analysis,
    db: cantools.database.can.Database | None = None,
) -> None:
    """Write what ``--parquet``/``--mcap`` ask for (paths checked by ``check_export_paths``)."""
    from odocan.host.outputs import OutputError, replaced

    if args.parquet is not None:
        from odocan.host.io.parquet import write_parquet

        try:
            write_parquet(args.parquet, frames, analysis, db)
        except OSError as exc:
            raise OutputError(f"--parquet {args.parquet}: {exc.strerror or exc}") from None
    if args.mcap is not None:
        from odocan.host.io.mcap import write_mcap

        with replaced(args.mcap, "--mcap") as target:  # an older MCAP kept on a full disk
            try:
                write_mcap(target, frames, analysis, db)
            except RuntimeError as exc:  # foxglove's writer raises RuntimeError on I/O
                raise OSError(str(exc).splitlines()[0]) from None


FOXGLOVE_PORT = 8765  # Foxglove's usual WebSocket port: --foxglove's default


# --- output paths --------------------------------------------------------------------------


def check_export_paths(parquet_dir: Path | None, mcap_path: Path | None) -> None:
    """Refuse, before any work, a ``--parquet DIR`` or ``--mcap PATH`` that cannot be written."""
    if parquet_dir is not None:
        if parquet_dir.exists() and not parquet_dir.is_dir():
            raise ConfigurationError(f"--parquet {parquet_dir}: not a directory")
        _check_writable_dir("--parquet", parquet_dir, parquet_dir if parquet_dir.is_dir()
                            else parquet_dir.parent)
    if mcap_path is not None:
        from odocan.host.outputs import check_writable

        check_writable(mcap_path, "--mcap")  # a directory, a device (/dev/full), no permission


def _check_writable_dir(option: str, path: Path, directory: Path) -> None:
    from odocan.host.outputs import check_writable_dir

    check_writable_dir(directory, option, path)


# --- Foxglove messages (JSON, field names of foxglove's schemas) ------------------------------


def column_name(signal: Signal) -> str:
    """``X`` in ``m`` -> ``X_m``; ``m/s`` -> ``_m_per_s``; no unit or ``-`` -> the bare name."""
    unit = (signal.unit or "").strip()
    if unit in ("", "-"):
        return signal.name
    unit = re.sub(r"[^0-9A-Za-z]+", "_", unit.replace("/", "_per_")).strip("_")
    return f"{signal.name}_{unit}"


def to_ns(timestamp_s: float) -> int:
    """Seconds to integer nanoseconds (log times), never negative."""
    return max(0, round(timestamp_s * 1e9))


def foxglove_time(t_ns: int) -> dict[str, int]:
    """foxglove ``time``: ``{"sec", "nsec"}`` of a non-negative time in nanoseconds."""
    sec, nsec = divmod(max(0, t_ns), 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


def yaw_quaternion(heading_rad: float) -> dict[str, float]:
    """A rotation about z by ``heading_rad`` as a foxglove ``Quaternion``."""
    half = 0.5 * heading_rad
    return {"x": 0.0, "y": 0.0, "z": math.sin(half), "w": math.cos(half)}


def pose_in_frame(t_ns: int, x_m: float, y_m: float, heading_rad: float) -> dict[str, Any]:
    """A ``foxglove.PoseInFrame`` in the ``odom`` frame."""
    return {
        "timestamp": foxglove_time(t_ns),
        "frame_id": ODOM_FRAME,
        "pose": {
            "position": {"x": x_m, "y": y_m, "z": 0.0},
            "orientation": yaw_quaternion(heading_rad),
        },
    }


def frame_transform(
    t_ns: int, child: str, x_m: float, y_m: float, heading_rad: float
) -> dict[str, Any]:
    """A ``foxglove.FrameTransform`` from ``odom`` to ``child``."""
    return {
        "timestamp": foxglove_time(t_ns),
        "parent_frame_id": ODOM_FRAME,
        "child_frame_id": child,
        "translation": {"x": x_m, "y": y_m, "z": 0.0},
        "rotation": yaw_quaternion(heading_rad),
    }


def can_frame(
    t_ns: int, can_id: int, data: bytes, *, extended: bool, remote: bool, error: bool
) -> dict[str, Any]:
    """An ``odocan.CanFrame``: one raw frame, its payload as a list of byte values."""
    return {
        "timestamp": foxglove_time(t_ns), "id": can_id, "extended": extended, "remote": remote,
        "error": error, "dlc": len(data), "data": list(data),
    }


def pose_error(t_ns: int, position_error_m: float, heading_error_rad: float) -> dict[str, Any]:
    """An ``odocan.PoseError``: on-board minus reference or truth."""
    return {
        "timestamp": foxglove_time(t_ns),
        "position_error_m": position_error_m,
        "heading_error_rad": heading_error_rad,
    }


TIME_SCHEMA = {
    "type": "object",
    "properties": {"sec": {"type": "integer", "minimum": 0},
                   "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}},
}
_VECTOR3 = {"type": "object", "properties": {a: {"type": "number"} for a in "xyz"}}
_QUATERNION = {"type": "object", "properties": {a: {"type": "number"} for a in "xyzw"}}
SCHEMAS: dict[str, dict[str, Any]] = {
    "foxglove.PoseInFrame": {
        "type": "object",
        "properties": {
            "timestamp": TIME_SCHEMA,
            "frame_id": {"type": "string"},
            "pose": {"type": "object",
                     "properties": {"position": _VECTOR3, "orientation": _QUATERNION}},
        },
    },
    "foxglove.FrameTransform": {
        "type": "object",
        "properties": {
            "timestamp": TIME_SCHEMA,
            "parent_frame_id": {"type": "string"},
            "child_frame_id": {"type": "string"},
            "translation": _VECTOR3,
            "rotation": _QUATERNION,
        },
    },
    "odocan.PoseError": {
        "type": "object",
        "properties": {"timestamp": TIME_SCHEMA, "position_error_m": {"type": "number"},
                       "heading_error_rad": {"type": "number"}},
    },
    "odocan.CanFrame": {
        "type": "object",
        "properties": {
            "timestamp": TIME_SCHEMA,
            "id": {"type": "integer"},
            "extended": {"type": "boolean"},
            "remote": {"type": "boolean"},
            "error": {"type": "boolean"},
            "dlc": {"type": "integer"},
            "data": {"type": "array", "items": {"type": "integer"}},
        },
    },
}


def json_schema(name: str) -> bytes:
    """The JSON schema text of ``name`` (``title`` = the schema name)."""
    return json.dumps({"title": name, **SCHEMAS[name]}).encode()
