"""``odocan analyze LOG...``: a fleet's archive in parallel processes and on a Dask cluster.

Three short drives (different seeds, .log / .asc / .blf, one in a subfolder) are analysed one by
one with ``odocan analyze LOG --report`` (today's single-log path) and then as a batch: the batch
must give each log the very report the single analysis gave, whatever the engine.
"""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from odocan.host.cli import batch
from odocan.host.cli.app import main
from odocan.host.io.logs import (
    FrameArrays,
    LogFormatError,
    parse_candump,
    parse_candump_chunks,
    read_log,
)
from tests.test_cli_run import assert_usage_error, run_cli

SAME = ("robot", "integrator", "frames", "onboard_vs_reference", "onboard_vs_truth",
        "final_onboard_pose", "e2e", "passed", "inputs")
DRIVES = {"a.log": 5, "sub/b.asc": 6, "sub/deeper/c.blf": 7}  # log -> seed


@pytest.fixture(scope="module")
def archive(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, dict[str, Any]]]:
    """A folder of three 4 s drives, and each log's single-analysis report (by relative name)."""
    root = tmp_path_factory.mktemp("archive")
    singles: dict[str, dict[str, Any]] = {}
    for name, seed in DRIVES.items():
        log = root / name
        log.parent.mkdir(parents=True, exist_ok=True)
        assert main(["run", "--duration", "4", "--seed", str(seed), "--log", str(log)]) == 0
        report = root.parent / f"{root.name}-{seed}.json"
        assert main(["analyze", str(log), "--report", str(report)]) == 0
        singles[name] = json.loads(report.read_text())
    (root / "notes.txt").write_text("not a log, and not picked up from a directory\n")
    return root, singles


def reports_by_log(directory: Path) -> dict[str, dict[str, Any]]:
    """The batch's JSON reports, keyed by the log path each one names."""
    reports = [json.loads(p.read_text()) for p in directory.glob("*.json")]
    return {Path(r["inputs"]["log"]["path"]).as_posix(): r for r in reports}


def assert_same_reports(
    root: Path, singles: dict[str, dict[str, Any]], written: dict[str, dict[str, Any]]
) -> None:
    assert len(written) == len(singles)
    for name, single in singles.items():
        (got,) = [r for path, r in written.items() if path.endswith(name)]
        for key in SAME:
            if key == "inputs":  # the same log file: same SHA-256
                assert got[key]["log"]["sha256"] == single[key]["log"]["sha256"]
            else:
                assert got[key] == single[key], (name, key)


def test_a_directory_in_parallel_gives_each_log_its_single_report(
    capsys: pytest.CaptureFixture[str], tmp_path: Path,
    archive: tuple[Path, dict[str, dict[str, Any]]],
) -> None:
    root, singles = archive
    code, out, err = run_cli(capsys, "analyze", str(root), "--jobs", "2",
                             "--report-dir", str(tmp_path / "reports"))
    assert (code, err) == (0, "")
    assert "odocan analyze: 3 logs" in out
    assert "3 PASS, 0 FAIL, 0 unreadable" in out
    for name in DRIVES:
        (row,) = [line for line in out.splitlines() if Path(name).name in line]
        frames = len(read_log(root / name))
        assert row.split()[1:3] == [str(frames), "PASS"], row
    names = sorted(p.name for p in (tmp_path / "reports").iterdir())
    assert names == ["a.log.json", "sub__b.asc.json", "sub__deeper__c.blf.json"]
    assert_same_reports(root, singles, reports_by_log(tmp_path / "reports"))


def test_a_failing_log_exits_1_and_is_named(
    capsys: pytest.CaptureFixture[str], archive: tuple[Path, dict[str, dict[str, Any]]]
) -> None:
    """A tolerance between two logs' largest errors: the one above it fails, alone."""
    root, singles = archive
    errors = sorted((singles[n]["onboard_vs_reference"]["max_position_error_m"], n)
                    for n in ("a.log", "sub/b.asc"))
    assert errors[0][0] < errors[1][0]
    tolerance = (errors[0][0] + errors[1][0]) / 2
    logs = [str(root / n) for n in ("a.log", "sub/b.asc")]
    code, out, err = run_cli(capsys, "analyze", *logs, "--tolerance", f"{tolerance!r}")
    assert code == 1
    worse = errors[1][1]
    assert err.splitlines() == [
        f"FAIL: 1 of 2 logs out of tolerance: {next(p for p in logs if p.endswith(worse))}"
    ]
    assert "1 PASS, 1 FAIL, 0 unreadable" in out


def test_good_and_unreadable_logs_analyse_the_good_and_name_the_bad(
    capsys: pytest.CaptureFixture[str], tmp_path: Path,
    archive: tuple[Path, dict[str, dict[str, Any]]],
) -> None:
    root, singles = archive
    garbage = tmp_path / "garbage.log"
    garbage.write_text("this is no candump line\n")
    empty = tmp_path / "empty_dir"
    empty.mkdir()
    code, out, err = run_cli(capsys, "analyze", str(root / "a.log"), str(garbage), str(empty),
                             "--report-dir", str(tmp_path / "reports"))
    assert code == 2
    (line,) = err.splitlines()
    assert line.startswith("error: 2 unreadable: ")
    assert str(garbage) in line
    assert str(empty) in line
    assert "a.log" not in line
    assert "1 PASS, 0 FAIL, 1 unreadable" in out
    (written,) = reports_by_log(tmp_path / "reports").values()
    assert written["onboard_vs_reference"] == singles["a.log"]["onboard_vs_reference"]


def test_a_directory_without_logs_is_a_usage_error(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    (tmp_path / "readme.txt").write_text("no logs here\n")
    code = main(["analyze", str(tmp_path), "--jobs", "2"])
    assert_usage_error(capsys, code, str(tmp_path), "no .log, .asc or .blf")


def test_an_unwritable_report_dir_is_refused_before_any_work(
    capsys: pytest.CaptureFixture[str], tmp_path: Path,
    archive: tuple[Path, dict[str, dict[str, Any]]],
) -> None:
    root, _ = archive
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    for target in (blocker, blocker / "below"):
        code = main(["analyze", str(root), "--report-dir", str(target)])
        assert_usage_error(capsys, code, "--report-dir", str(target))


def test_single_log_options_are_refused_for_many_logs(
    capsys: pytest.CaptureFixture[str], tmp_path: Path,
    archive: tuple[Path, dict[str, dict[str, Any]]],
) -> None:
    root, _ = archive
    code = main(["analyze", str(root), "--report", str(tmp_path / "r.json")])
    assert_usage_error(capsys, code, "--report", "--report-dir")
    assert not (tmp_path / "r.json").exists()


def _closed_port() -> int:
    """A local TCP port nobody listens on (bound, then released)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
    return port


def _dask_error_line(root: Path, address: str) -> str:
    """``odocan analyze ROOT --dask ADDRESS`` as a whole process (the timeout guards against a
    hang, it measures nothing): exit 2, nothing on stdout, its one stderr line."""
    done = subprocess.run(
        [sys.executable, "-m", "odocan", "analyze", str(root), "--dask", address,
         "--dask-timeout", "1"],
        capture_output=True, text=True, timeout=120, check=False,
    )
    assert done.returncode == 2, done
    assert done.stdout == ""
    (line,) = done.stderr.splitlines()
    return line


def test_an_unreachable_dask_scheduler_is_one_line_and_exit_2(
    archive: tuple[Path, dict[str, dict[str, Any]]],
) -> None:
    """As a whole process, so the test also proves the command ends (the subprocess timeout is a
    guard against a hang, not a measurement)."""
    root, _ = archive
    address = f"tcp://127.0.0.1:{_closed_port()}"
    line = _dask_error_line(root, address)
    assert line.startswith(f"error: --dask {address}: cannot connect within 1 s"), line


def test_a_peer_that_is_no_dask_scheduler_is_one_line_and_exit_2(
    archive: tuple[Path, dict[str, dict[str, Any]]],
) -> None:
    """A port that answers, but in another protocol (here: an HTTP error): no traceback, no
    hang, whatever Dask's client makes of the bytes."""
    root, _ = archive
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen()
        address = f"tcp://127.0.0.1:{server.getsockname()[1]}"

        def answer() -> None:
            for _ in range(8):  # the probe, then Dask's attempts
                try:
                    peer, _ = server.accept()
                except OSError:
                    return
                with peer:
                    peer.sendall(b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n" * 4)

        thread = threading.Thread(target=answer, daemon=True)
        thread.start()
        line = _dask_error_line(root, address)
    assert line.startswith(f"error: --dask {address}: no Dask scheduler answered within 1 s"), line


def test_a_dask_local_cluster_gives_the_same_reports(
    capsys: pytest.CaptureFixture[str], tmp_path: Path,
    archive: tuple[Path, dict[str, dict[str, Any]]],
) -> None:
    distributed = pytest.importorskip("distributed")
    root, singles = archive
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        code, out, err = run_cli(capsys, "analyze", str(root), "--dask", cluster.scheduler_address,
                                 "--report-dir", str(tmp_path / "reports"))
    assert (code, err) == (0, ""), out
    assert "3 PASS, 0 FAIL, 0 unreadable" in out
    assert_same_reports(root, singles, reports_by_log(tmp_path / "reports"))


def test_find_logs_recurses_and_names_what_gives_nothing(tmp_path: Path) -> None:
    (tmp_path / "x" / "y").mkdir(parents=True)
    for name in ("x/1.log", "x/y/2.ASC", "x/y/3.blf", "x/4.txt"):
        (tmp_path / name).write_text("")
    logs, problems = batch.find_logs([tmp_path / "x", tmp_path / "x" / "1.log",
                                      tmp_path / "missing"])
    assert [p.name for p in logs] == ["1.log", "2.ASC", "3.blf"]  # no duplicate, no .txt
    assert problems == [f"{tmp_path / 'missing'}: no such log file or directory"]


# --- one big log in bounded memory: the candump text parsed a chunk at a time ------------------


def assert_same_frames(got: FrameArrays, want: FrameArrays) -> None:
    assert len(got) == len(want)
    for name in ("timestamp_s", "can_id", "dlc", "data", "flags"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)


@pytest.mark.parametrize("chunk_bytes", [1, 37, 1000, 1 << 20])
def test_chunks_give_the_frames_of_one_whole_parse(
    archive: tuple[Path, dict[str, dict[str, Any]]], chunk_bytes: int
) -> None:
    """Every cut, down to one line per chunk, and odd lines (blank, CRLF, remote, error, FD,
    lowercase, extended) that take the slow path in some chunks and the fast one in others."""
    root, _ = archive
    odd = (b"\n(1.5) vcan0 123#R\r\n(1.6) vcan0 20000080#0000000000000000\n"
           b"(1.7) vcan0 1ABCDEF0#00112233 T\n(1.8) vcan0 0a1##1ab\n(1.9) vcan0 7ff#\n")
    content = (root / "a.log").read_bytes()
    content = content[:5000] + odd + content[5000:20000] + odd * 3 + content[20000:]
    whole = parse_candump(content, "x.log")
    assert_same_frames(parse_candump_chunks(content, len(content), "x.log", chunk_bytes), whole)


def test_a_bad_line_in_a_later_chunk_is_named_by_its_line_in_the_file() -> None:
    good = b"".join(b"(%d.000000) vcan0 123#0011\n" % i for i in range(300))
    content = good + b"(300.000000) vcan0 123#00112\n" + good
    with pytest.raises(LogFormatError) as whole:
        parse_candump(content, "x.log")
    with pytest.raises(LogFormatError) as chunked:
        parse_candump_chunks(content, len(content), "x.log", 1000)
    assert str(chunked.value) == str(whole.value)
    assert str(whole.value).startswith("x.log:301:")


def test_read_log_maps_the_file_and_keeps_the_partial_line_rule(tmp_path: Path,
        archive: tuple[Path, dict[str, dict[str, Any]]]) -> None:
    """read_log (mapped, chunked) on a log cut mid-line: the frames before the cut, the warning
    naming the cut line, as the whole-content parse says."""
    root, _ = archive
    content = (root / "a.log").read_bytes()
    cut = content[: content.rfind(b"\n", 0, len(content) // 2) + 12]  # a line cut after 11 bytes
    log = tmp_path / "cut.log"
    log.write_bytes(cut)
    warnings: list[str] = []
    frames = read_log(log, warn=warnings.append)
    kept = cut[: cut.rfind(b"\n") + 1]
    assert_same_frames(frames, parse_candump(kept))
    line = kept.count(b"\n") + 1
    assert warnings == [f"{log}: skipped 1 partial line at the end (line {line}, "
                        "cut mid-line: a recorder killed while writing?)"]


def test_a_lost_worker_is_its_logs_error_not_the_batchs_end() -> None:
    from concurrent.futures.process import BrokenProcessPool

    def died() -> batch.LogResult:
        raise BrokenProcessPool("a child process terminated abruptly")

    result = batch._outcome("x.log", died)
    assert (result.path, result.report, result.passed) == ("x.log", None, False)
    assert result.error == "worker lost: BrokenProcessPool: a child process terminated abruptly"
