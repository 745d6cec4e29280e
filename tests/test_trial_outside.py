"""What a user trying odocan from outside ran into, each case failing before its fix."""

from __future__ import annotations

import pytest

from tests.test_outside_inputs import _one_error_line


@pytest.mark.parametrize("bitrate", ["10000", "20000"])
def test_a_bus_too_slow_for_the_rig_is_named_not_called_a_bug(
    bitrate: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """At 10 and 20 kbit/s the rig's 720 frames/s cannot get through (a pose message never
    does): the error says the bus is too slow, not 'a bug, please report it'."""
    err = _one_error_line(capsys, ["run", "-b", bitrate, "--duration", "1"])
    assert "a bug" not in err
    assert f"at {bitrate} bit/s the bus cannot carry the rig's traffic" in err
    assert "frames still queued at the end" in err
