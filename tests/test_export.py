"""``--parquet`` and ``--mcap`` read back by other tools: DuckDB over the Parquet, the ``mcap``
reader over the MCAP, both compared with the JSON report of the same run, the decoded signals
with cantools' own per-frame decoder, the Foxglove messages with the Foxglove SDK's classes.
"""

from __future__ import annotations

import errno
import json
import math
import os
from pathlib import Path
from typing import Any

import duckdb
import foxglove.messages as fm
import pytest
from mcap.reader import make_reader

from odocan.host.cli.app import main
from odocan.host.io.export import check_export_paths
from odocan.sim.contract import database
from odocan.sim.exceptions import ConfigurationError

ARGS = ["run", "--duration", "6", "--seed", "3", "--errors", "ed=1.01,eb=1.02"]


@pytest.fixture(scope="module")
def run_outputs(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict[str, Any], Path, Path]:
    """One ``odocan run`` with --report, --parquet and --mcap: (report, DIR, PATH)."""
    tmp = tmp_path_factory.mktemp("export")
    report, parquet, mcap = tmp / "report.json", tmp / "pq", tmp / "run.mcap"
    code = main([*ARGS, "--report", str(report), "--parquet", str(parquet), "--mcap", str(mcap)])
    assert code == 0
    return json.loads(report.read_text()), parquet, mcap


def relation(query: str) -> duckdb.DuckDBPyRelation:
    result = duckdb.sql(query)
    assert result is not None
    return result


def sql(query: str, parquet: Path) -> list[tuple[Any, ...]]:
    """A DuckDB query over the tables of ``parquet`` (``{name}`` -> its ``name.parquet``)."""
    names = {p.stem: f"'{p}'" for p in parquet.glob("*.parquet")}
    return relation(query.format(**names)).fetchall()


# --- Parquet ---------------------------------------------------------------------------------


def test_duckdb_recomputes_the_reports_errors(
    run_outputs: tuple[dict[str, Any], Path, Path],
) -> None:
    report, parquet, _ = run_outputs
    (count, max_pos, max_head, max_recomputed), = sql(
        "select count(*), max(position_error_m), max(abs(heading_error_rad)), "
        "max(sqrt((onboard_x_m - reference_x_m)^2 + (onboard_y_m - reference_y_m)^2)) "
        "from {series}", parquet,
    )
    ref = report["onboard_vs_reference"]
    assert count == report["samples"]["onboard"] > 250
    assert max_pos == ref["max_position_error_m"]
    assert max_head == ref["max_heading_error_rad"]
    assert max_recomputed == pytest.approx(ref["max_position_error_m"], rel=1e-12, abs=1e-18)
    columns = {row[0] for row in sql("select column_name from (describe {truth})", parquet)}
    assert columns >= {"timestamp_s", "truth_x_m", "truth_y_m", "truth_heading_rad",
                       "truth_position_error_m", "truth_heading_error_rad"}
    (t_count, t_max), = sql("select count(*), max(truth_position_error_m) from {truth}", parquet)
    truth = report["onboard_vs_truth"]
    assert t_count == report["samples"]["truth_compared"] > 50
    assert t_max == truth["max_position_error_m"] > 1e-3  # the errors make the truth drift
    # where an on-board sample names the truth sample's encoder frame, the error is theirs
    (joined, off), = sql(
        "select count(*), count(*) filter (where abs(t.truth_position_error_m - "
        "sqrt((s.onboard_x_m - t.truth_x_m)^2 + (s.onboard_y_m - t.truth_y_m)^2)) > 1e-12) "
        "from {truth} t join {series} s using (timestamp_s)", parquet,
    )
    assert joined > 25
    assert off == 0


def test_the_last_sample_is_the_reports_final_pose(
    run_outputs: tuple[dict[str, Any], Path, Path],
) -> None:
    report, parquet, _ = run_outputs
    (x, y, h), = sql(
        "select onboard_x_m, onboard_y_m, onboard_heading_unwrapped_rad from {series} "
        "order by timestamp_s desc limit 1", parquet,
    )
    final = report["final_onboard_pose"]
    assert (x, y, h) == (final["x_m"], final["y_m"], final["heading_unwrapped_rad"])


def test_the_pose_series_is_the_decoded_pose_frames(
    run_outputs: tuple[dict[str, Any], Path, Path],
) -> None:
    """ODOM_POSE_X.X_m (decoded, scaled) is the on-board x of the series, frame by frame."""
    _, parquet, _ = run_outputs
    (mismatch, matched), = sql(
        "select count(*) filter (where abs(p.X_m - s.onboard_x_m) > 1e-9), count(*) "
        "from {series} s join {WHEEL_ENCODERS} e on e.timestamp_s = s.timestamp_s "
        "join {ODOM_POSE_X} p on p.index > e.index and p.ENC_COUNTER = e.COUNTER "
        "and p.timestamp_s < e.timestamp_s + 0.01", parquet,
    )
    assert matched >= 250
    assert mismatch == 0


def test_signals_equal_cantools_decode_per_frame(
    run_outputs: tuple[dict[str, Any], Path, Path],
) -> None:
    """Every message table against ``Database.decode_message`` of the raw bytes, with the unit
    in each column name; multiplexed signals null off their page."""
    _, parquet, _ = run_outputs
    db = database()
    raw = {
        row[0]: row[1:]
        for row in relation(f"select row_number() over () - 1, can_id, data "
                              f"from '{parquet / 'frames.parquet'}'").fetchall()
    }
    checked = 0
    for path in sorted(parquet.glob("[A-Z]*.parquet")):
        message = db.get_message_by_name(path.stem)
        rel = relation(f"select * from '{path}' using sample 40 rows (reservoir, 7)")
        columns = rel.columns
        for row in rel.fetchall():
            values = dict(zip(columns, row, strict=True))
            can_id, data = raw[values["index"]]
            assert can_id == message.frame_id
            expected = dict(db.decode_message(can_id, data, decode_choices=False))
            for signal in message.signals:
                unit = signal.unit if signal.unit not in (None, "", "-") else ""
                name = f"{signal.name}_{unit.replace('/', '_per_')}" if unit else signal.name
                got = values[name]
                if signal.name not in expected:
                    assert got is None, (path.stem, name)
                else:
                    assert got == pytest.approx(expected[signal.name], rel=1e-12), (path.stem, name)
                    checked += 1
    assert checked > 500


def test_e2e_column_agrees_with_the_report(run_outputs: tuple[dict[str, Any], Path, Path]) -> None:
    report, parquet, _ = run_outputs
    for name, counts in report["e2e"].items():
        path = parquet / f"{name}.parquet"
        if path.exists():
            (ok,), = relation(f"select count(*) filter (where e2e_ok) from '{path}'").fetchall()
            assert ok == counts["ok"], name


def test_report_rides_in_the_series_metadata(
    run_outputs: tuple[dict[str, Any], Path, Path],
) -> None:
    import pyarrow.parquet as pq

    report, parquet, _ = run_outputs
    metadata = pq.read_schema(parquet / "series.parquet").metadata
    stored = json.loads(metadata[b"odocan.report"])
    assert stored["onboard_vs_reference"] == report["onboard_vs_reference"]


# --- MCAP ------------------------------------------------------------------------------------


def read_mcap(path: Path) -> dict[str, list[tuple[str, int, dict[str, Any]]]]:
    """topic -> [(schema name, log time ns, decoded JSON)] with the ``mcap`` reader."""
    topics: dict[str, list[tuple[str, int, dict[str, Any]]]] = {}
    with path.open("rb") as stream:
        for schema, channel, message in make_reader(stream).iter_messages(log_time_order=True):
            assert schema is not None
            assert schema.encoding == "jsonschema"
            assert channel.message_encoding == "json"
            assert json.loads(schema.data)["title"] == schema.name
            topics.setdefault(channel.topic, []).append(
                (schema.name, message.log_time, json.loads(message.data))
            )
    return topics


@pytest.fixture(scope="module")
def mcap_topics(run_outputs: tuple[dict[str, Any], Path, Path]) -> dict[str, Any]:
    return read_mcap(run_outputs[2])


def heading_of(quaternion: dict[str, float]) -> float:
    assert quaternion["x"] == quaternion["y"] == 0.0
    return 2 * math.atan2(quaternion["z"], quaternion["w"])


def wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


def test_mcap_poses_and_errors_match_the_report(
    run_outputs: tuple[dict[str, Any], Path, Path], mcap_topics: dict[str, Any]
) -> None:
    report, _, _ = run_outputs
    onboard = mcap_topics["/pose/onboard"]
    assert {schema for schema, _, _ in onboard} == {"foxglove.PoseInFrame"}
    assert len(onboard) == report["samples"]["onboard"]
    assert len(mcap_topics["/pose/reference"]) == len(onboard)
    assert len(mcap_topics["/pose/truth"]) == report["samples"]["truth_compared"] > 50
    _, t_ns, last = onboard[-1]
    final = report["final_onboard_pose"]
    assert last["frame_id"] == "odom"
    assert last["timestamp"] == {"sec": t_ns // 10**9, "nsec": t_ns % 10**9}
    assert last["pose"]["position"] == {"x": final["x_m"], "y": final["y_m"], "z": 0.0}
    assert abs(wrap(heading_of(last["pose"]["orientation"]) - final["heading_rad"])) < 1e-12
    errors = mcap_topics["/errors/reference"]
    assert max(m["position_error_m"] for _, _, m in errors) == (
        report["onboard_vs_reference"]["max_position_error_m"]
    )
    truth_errors = mcap_topics["/errors/truth"]
    assert max(abs(m["heading_error_rad"]) for _, _, m in truth_errors) == (
        report["onboard_vs_truth"]["max_heading_error_rad"]
    )


def test_mcap_transform_tree_follows_the_poses(mcap_topics: dict[str, Any]) -> None:
    tf = mcap_topics["/tf"]
    children = {m["child_frame_id"] for _, _, m in tf}
    assert children == {"base_link", "reference_link", "truth_link"}
    assert {m["parent_frame_id"] for _, _, m in tf} == {"odom"}
    base = [(t, m) for _, t, m in tf if m["child_frame_id"] == "base_link"]
    poses = mcap_topics["/pose/onboard"]
    assert len(base) == len(poses)
    for (t, transform), (_, t_pose, pose) in zip(base, poses, strict=True):
        assert t == t_pose
        assert transform["translation"] == pose["pose"]["position"]
        assert transform["rotation"] == pose["pose"]["orientation"]


def test_mcap_raw_frames_are_the_logged_bytes(
    run_outputs: tuple[dict[str, Any], Path, Path], mcap_topics: dict[str, Any]
) -> None:
    _, parquet, _ = run_outputs
    frames = relation(
        f"select can_id, data from '{parquet / 'frames.parquet'}'"
    ).fetchall()
    can = mcap_topics["/can/frames"]
    assert len(can) == len(frames) > 1000
    by_time = sorted(((m["id"], bytes(m["data"])) for _, _, m in can))
    assert by_time == sorted((can_id, bytes(data)) for can_id, data in frames)
    decoded = mcap_topics["/can/WHEEL_ENCODERS"]
    assert {"LEFT_COUNT_count", "RIGHT_COUNT_count", "COUNTER"} <= set(decoded[0][2])


def test_mcap_messages_fit_the_foxglove_sdks_classes(mcap_topics: dict[str, Any]) -> None:
    """Foxglove's own classes take our JSON field names as keywords (a misspelt field fails)."""
    _, _, pose = mcap_topics["/pose/truth"][-1]
    fm.PoseInFrame(
        timestamp=fm.Timestamp(**pose["timestamp"]),
        frame_id=pose["frame_id"],
        pose=fm.Pose(
            position=fm.Vector3(**pose["pose"]["position"]),
            orientation=fm.Quaternion(**pose["pose"]["orientation"]),
        ),
    )
    _, _, tf = mcap_topics["/tf"][-1]
    fm.FrameTransform(
        timestamp=fm.Timestamp(**tf["timestamp"]),
        parent_frame_id=tf["parent_frame_id"],
        child_frame_id=tf["child_frame_id"],
        translation=fm.Vector3(**tf["translation"]),
        rotation=fm.Quaternion(**tf["rotation"]),
    )
    with pytest.raises(TypeError):
        fm.Vector3(**{"x": 1.0, "y": 2.0, "zz": 0.0})


def test_mcap_metadata_holds_the_report(run_outputs: tuple[dict[str, Any], Path, Path]) -> None:
    report, _, mcap = run_outputs
    with mcap.open("rb") as stream:
        records = list(make_reader(stream).iter_metadata())
    assert [r.name for r in records] == ["odocan.report"]
    assert json.loads(records[0].metadata["json"])["passed"] == report["passed"]


# --- analyze and bad paths -------------------------------------------------------------------


def test_analyze_exports_a_log(tmp_path: Path) -> None:
    log = tmp_path / "drive.log"
    assert main([*ARGS, "--log", str(log)]) == 0
    report_path, parquet, mcap = tmp_path / "r.json", tmp_path / "out" / "pq", tmp_path / "a.mcap"
    (tmp_path / "out").mkdir()
    code = main(["analyze", str(log), "--report", str(report_path), "--parquet", str(parquet),
                 "--mcap", str(mcap)])
    assert code == 0
    report = json.loads(report_path.read_text())
    (max_pos,), = sql("select max(position_error_m) from {series}", parquet)
    assert max_pos == report["onboard_vs_reference"]["max_position_error_m"]
    assert len(read_mcap(mcap)["/pose/onboard"]) == report["samples"]["onboard"]


@pytest.mark.parametrize(
    ("option", "make", "message"),
    [
        ("--parquet", lambda d: (d / "file").write_text("x") and d / "file", "not a directory"),
        ("--parquet", lambda d: d / "missing" / "pq", "does not exist"),
        ("--mcap", lambda d: d, "is a directory"),
        ("--mcap", lambda d: d / "missing" / "x.mcap", "does not exist"),
    ],
)
def test_unwritable_outputs_fail_before_the_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], option: str, make: Any, message: str
) -> None:
    target = make(tmp_path)
    report = tmp_path / "report.json"
    code = main([*ARGS, "--report", str(report), option, str(target)])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith(f"error: {option} {target}")
    assert message in err
    assert err.count("\n") == 1
    assert not report.exists()  # refused before the drive ran


def test_read_only_directory_is_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Creating the file is refused, as for any user but root in a read-only directory.

    The check proves a path writable by opening it (host/outputs.py, since permission bits
    lied to root about /proc), so the refusal is made at that open: ``os.open`` of the target
    raises EACCES, and the error is one line naming the option, the path and the reason."""
    target = tmp_path / "x.mcap"
    real_open = os.open

    def refusing_open(path: Any, flags: int, mode: int = 0o777) -> int:
        if Path(path) == target:
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path))
        return real_open(path, flags, mode)

    monkeypatch.setattr("odocan.host.outputs.os.open", refusing_open)
    with pytest.raises(ConfigurationError) as refused:
        check_export_paths(None, target)
    assert str(refused.value) == f"--mcap {target}: {os.strerror(errno.EACCES)}"
    assert not target.exists()


def test_mcap_is_written_in_log_time_order(run_outputs: tuple[dict[str, Any], Path, Path]) -> None:
    """The streams (frames, each message, each pose and error series) are merged by time, so
    the file plays without a reorder."""
    with run_outputs[2].open("rb") as stream:
        times = [m.log_time for _, _, m in make_reader(stream).iter_messages(log_time_order=False)]
    assert len(times) > 5000
    assert times == sorted(times)
