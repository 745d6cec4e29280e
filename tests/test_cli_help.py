"""Names and help: every option of every subcommand says what it is and what its default is;
every ``--duration`` says which seconds it counts."""

from __future__ import annotations

import argparse

import pytest

from odocan.host.cli.app import SUBCOMMANDS, build_parser, main

DURATION_MEANING = {
    "run": "SIMULATED seconds",
    "vectors": "SCENARIO seconds",
    "sim": "wall-clock seconds",
    "firmware": "wall-clock seconds",
    "monitor": "wall-clock seconds",
    "bridge": "wall-clock seconds",
    "fleet": "WALL-CLOCK seconds",
}


def _subparsers() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


@pytest.mark.parametrize("command", SUBCOMMANDS)
def test_every_option_has_help_showing_its_default(
    command: str, capsys: pytest.CaptureFixture[str]
) -> None:
    sub = _subparsers()[command]
    for action in sub._actions:
        if isinstance(action, argparse._HelpAction) or not action.option_strings:
            continue
        assert action.help, f"{command} {action.option_strings}: no help"
        shown = sub.formatter_class(prog="x")._get_help_string(action) or ""
        flag = isinstance(action, argparse._StoreTrueAction) or action.required
        assert flag or "default" in shown, f"{command} {action.option_strings}: {shown!r}"
    with pytest.raises(SystemExit):
        main([command, "--help"])
    assert "default" in capsys.readouterr().out


@pytest.mark.parametrize(("command", "meaning"), DURATION_MEANING.items())
def test_duration_says_which_seconds(command: str, meaning: str) -> None:
    action = _subparsers()[command]._option_string_actions["--duration"]
    assert meaning in (action.help or "")


def test_fleet_count_and_profile_do_not_clash() -> None:
    fleet = _subparsers()["fleet"]
    count = fleet._option_string_actions["--count"]
    assert fleet._option_string_actions["-n"] is count
    assert fleet._option_string_actions["--robots"] is count  # the old name, kept as an alias
    assert fleet._option_string_actions["--robot"].dest == "robot"


def test_monitor_broker_has_the_bridge_s_name() -> None:
    monitor = _subparsers()["monitor"]
    assert monitor._option_string_actions["--broker"] is monitor._option_string_actions["--mqtt"]
    assert "--broker" in _subparsers()["bridge"]._option_string_actions


def test_bare_help_read_from_the_sources_is_the_full_parser_s_help() -> None:
    """``odocan --help`` reads each command's one-line help from its module's source: the text
    is exactly what building every subparser prints."""
    from odocan.host.cli.app import summary_parser

    cheap = summary_parser()
    assert cheap is not None
    assert cheap.format_help() == build_parser().format_help()
