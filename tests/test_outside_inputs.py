"""Bad input found from outside: each is one ``error: ...`` line and exit 2, never a traceback.

Every case here printed a traceback (exit 1) or was taken silently before its fix.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from odocan.host.cli.app import main
from odocan.host.mqtt.broker import BrokerURL
from odocan.sim.exceptions import ConfigurationError


def _one_error_line(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    code = main(argv)
    out, err = capsys.readouterr()
    assert code == 2, (out, err)
    assert err.count("\n") == 1, err
    assert err.startswith("error: "), err
    return err


@pytest.mark.parametrize(
    ("url", "why"),
    [
        ("mqtt://[::1", "Invalid IPv6 URL"),  # a traceback (ValueError from urlsplit)
        ("mqtt://[zz]:1883", "does not appear to be an IPv4 or IPv6 address"),
        ("mqtts://broker:0", "port 0"),  # was taken as the default 8883
        ("mqtt://broker:0", "port 0"),
    ],
)
def test_a_malformed_broker_url_is_refused_in_one_line(url: str, why: str) -> None:
    with pytest.raises(ConfigurationError, match=why):
        BrokerURL.parse(url)


@pytest.mark.parametrize("command", ["bridge", "fleet", "monitor"])
def test_every_mqtt_command_refuses_a_malformed_broker_url(
    command: str, capsys: pytest.CaptureFixture[str]
) -> None:
    err = _one_error_line(capsys, [command, "--broker", "mqtt://[::1"])
    assert "--broker 'mqtt://[::1'" in err


@pytest.fixture(scope="module")
def vectors_json(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    import json

    out = tmp_path_factory.mktemp("vectors")
    assert main(["vectors", "--out", str(out), "--duration", "0.1"]) == 0
    data: dict[str, object] = json.loads((out / "vectors.json").read_text())
    return data


def _case0(data: dict[str, object]) -> dict[str, object]:
    cases = data["cases"]
    assert isinstance(cases, list)
    case: dict[str, object] = cases[0]
    return case


@pytest.mark.parametrize(
    "edit",
    [
        lambda d: [],  # a JSON list: AttributeError
        lambda d: None,
        lambda d: {**d, "cases": 5},  # TypeError: 'int' object is not iterable
        lambda d: {**d, "cases": [5]},
        lambda d: {**d, "cases": [{**_case0(d), "rows": 7}]},
        lambda d: {**d, "cases": [{**_case0(d), "rows": [{}]}]},  # KeyError: 'left_count'
        lambda d: {**d, "cases": [{**_case0(d), "rows": [{"left_count": "a"}]}]},
        lambda d: {**d, "cases": [{**_case0(d), "rows": [{"left_count": 1.5}]}]},
        lambda d: {**d, "cases": [{**_case0(d), "name": "../../x"}]},  # read outside --out
        lambda d: {**d, "cases": [{**_case0(d), "name": 5}]},
        lambda d: {**d, "params": {**d["params"], "counts_per_rev": "x"}},
    ],
)
def test_vectors_check_refuses_a_malformed_vector_file_in_one_line(
    edit: object, vectors_json: dict[str, object], tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    import json

    assert callable(edit)
    (tmp_path / "vectors.json").write_text(json.dumps(edit(vectors_json)))
    err = _one_error_line(capsys, ["vectors", "--out", str(tmp_path), "--check"])
    assert f"{tmp_path / 'vectors.json'}: " in err


@pytest.mark.parametrize("stamp", ["nan", "inf", "-inf", "NaN", "infinity"])
@pytest.mark.parametrize("stream", ["never", "always"])
def test_a_candump_line_with_a_non_finite_timestamp_is_refused(
    stamp: str, stream: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """'(nan)' was taken: the summary said 'nan s simulated, measured load nan%' and PASS."""
    good = tmp_path / "good.log"
    assert main(["run", "--duration", "1", "--log", str(good)]) == 0
    lines = good.read_text().splitlines(keepends=True)
    bad = tmp_path / "bad.log"
    bad.write_text("".join(lines[:50]) + f"({stamp}) vcan0 100#00\n" + "".join(lines[50:]))
    capsys.readouterr()
    err = _one_error_line(capsys, ["analyze", str(bad), "--stream", stream])
    assert err == f"error: {bad}:51: bad timestamp '({stamp})' (not a finite number)\n"


def test_replay_of_a_directory_or_a_pipe_says_what_it_is(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Both said 'no such log file', though the path is there."""
    import os

    err = _one_error_line(capsys, ["replay", str(tmp_path)])
    assert err == f"error: {tmp_path}: a directory, not a log file\n"
    pipe = tmp_path / "drive.log"
    os.mkfifo(pipe)
    err = _one_error_line(capsys, ["replay", str(pipe)])
    assert err == f"error: {pipe}: not a regular file (a pipe, device or socket)\n"
    err = _one_error_line(capsys, ["replay", str(tmp_path / "missing.log")])
    assert err == f"error: {tmp_path / 'missing.log'}: no such log file\n"


def test_a_bus_that_fails_to_open_leaves_no_second_line(
    capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture
) -> None:
    """'-i udp_multicast -c notanip' printed its error, then python-can's 'UdpMulticastBus was
    not properly shut down' from the half-made bus's ``__del__``."""
    import gc

    _one_error_line(capsys, ["monitor", "-i", "udp_multicast", "-c", "notanip", "--json",
                             "--duration", "1"])
    gc.collect()
    assert "not properly shut down" not in caplog.text


def test_a_robot_profile_that_is_not_utf8_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A TOML file of other bytes (a binary picked by mistake) was a UnicodeDecodeError
    traceback: tomllib decodes before it parses, and only its TOMLDecodeError was caught."""
    profile = tmp_path / "robot.toml"
    profile.write_bytes(b"\xff\xfename = 'x'\n")
    err = _one_error_line(capsys, ["run", "--duration", "1", "--robot", str(profile)])
    assert err.startswith(f"error: malformed TOML in {profile}: not UTF-8 text"), err


def _odocan_with_memory_limit(*argv: str) -> tuple[int, str]:
    """``python -m odocan ARGV`` in a process of at most 3 GB of address space: a regression
    that reads /dev/zero whole fails with MemoryError here instead of taking the machine."""
    import os

    from tests.limited import run_limited

    root = Path(__file__).resolve().parents[1]
    done = run_limited(list(argv), address_bytes=3 << 30, cwd=root,
                       env={**os.environ, "PYTHONPATH": str(root)}, timeout=120)
    return done.returncode, done.stderr


@pytest.mark.parametrize(
    ("argv", "error"),
    [
        (["bridge", "-i", "virtual", "--broker", "mqtt://user@127.0.0.1:1",
          "--password-file", "/dev/zero"],
         "error: --password-file /dev/zero: not a regular file\n"),
        (["busload", "--dbc", "/dev/zero"],
         "error: cannot read DBC /dev/zero: not a regular file\n"),
    ],
)
def test_an_endless_device_as_an_input_file_is_refused_unread(
    argv: list[str], error: str
) -> None:
    """Both read /dev/zero until the kernel killed them (exit 137 on this 24 GB machine)."""
    assert _odocan_with_memory_limit(*argv) == (2, error)
