"""The host's E2E window on messages sent as several frames a cycle (issue #11, rule 3: the
evidence the judges use): ODOM_STATUS (the summary and one rotating page every 100 ms) and
SIM_TRUTH (its three parts every 100 ms) step their COUNTER by 2 and 3 a cycle.

Before the fix the host widened their window by one a cycle (one "receive period" a cycle, at
least one a frame): after a burst took both status frames of two cycles off the bus, the next
summary came 5 counts on with a window of 4, WRONG_SEQUENCE, and the window fell behind by one a
cycle until it reached 15: on the 30 s burst drive of test_wrap_after_gaps, 118 of 437 good
ODOM_STATUS frames and 319 of 683 SIM_TRUTH frames refused, every one of them the sender's next
frame (checked here). AUTOSAR's receiver calls E2E_P02Check once per frame it expects, so the
window grows by the frames a cycle (the DBC's ``E2EFramesPerCycle``).

The checker is the test's own: python-can reads the log, cantools decodes PAGE/PART and COUNTER
and checks the Profile 2 CRC (``cantools.autosar``); the sender's frame number is the tick
(bus time over the cycle) times the frames a cycle plus the frame's slot in its tick.
"""

from __future__ import annotations

from pathlib import Path

import can
import cantools.autosar
import numpy as np
import pytest

from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.protocol.e2e import check_frames
from odocan.host.protocol.e2e_live import E2EMonitor
from tests.dbc_typed import dbc_attribute, load_can_dbc, number

DBC = Path(__file__).resolve().parents[1] / "odocan" / "dbc" / "odocan.dbc"
PAGED = {"ODOM_STATUS": (2, "PAGE"), "SIM_TRUTH": (3, "PART")}  # frames a cycle, multiplexer


@pytest.fixture(scope="module")
def burst_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The burst drive of test_wrap_after_gaps (a correct firmware, kobuki), logged."""
    log = tmp_path_factory.mktemp("paged") / "burst.log"
    code = main(["run", "--scenario", "random", "--duration", "30",
                 "--faults", "burst=0.05:6,seed=3", "--log", str(log)])
    assert code == 0
    return log


def _sender_verdicts(log: Path, name: str) -> dict[int, bool]:
    """Per frame of ``name`` whose CRC holds (its row in the log): whether a receiver that
    follows the sender's real counter takes it (the sender's next frames: True; one it has
    passed: False). Frames after a gap of 16 or more of the sender's frames are left out (mod 16
    no receiver can tell them)."""
    message = load_can_dbc(DBC).get_message_by_name(name)
    ids = [int(v) for v in dbc_attribute(message, "E2EDataIDs").split(",")]
    frames_a_cycle, mux = PAGED[name]
    assert message.cycle_time is not None
    cycle_s = message.cycle_time / 1000.0
    verdicts: dict[int, bool] = {}
    first_s: float | None = None
    last: int | None = None
    with can.LogReader(str(log)) as reader:
        for row, msg in enumerate(reader):
            if msg.arbitration_id != message.frame_id or msg.is_error_frame:
                continue
            data = bytes(msg.data)
            counter = data[1] & 0xF
            if not cantools.autosar.check_profile2_crc(data, ids[counter]):
                continue
            signals = message.decode(data, decode_choices=False, scaling=False)
            assert isinstance(signals, dict)
            slot = min(int(number(signals[mux])), frames_a_cycle - 1)  # ODOM_STATUS: 0, then 1..
            first_s = msg.timestamp if first_s is None else first_s
            seq = frames_a_cycle * round((msg.timestamp - first_s) / cycle_s) + slot
            assert counter == seq % 16, (name, row)  # the model of the sender holds
            if last is not None and seq - last >= 16:
                last = seq
                continue
            verdicts[row] = last is None or seq > last
            last = seq if verdicts[row] else last
    return verdicts


@pytest.mark.parametrize("name", sorted(PAGED))
def test_the_host_takes_every_next_frame_of_a_paged_message(burst_log: Path, name: str) -> None:
    """Whole log (``check_frames``) and live (``E2EMonitor``) alike take exactly the frames a
    receiver following the sender's counter takes."""
    verdicts = _sender_verdicts(burst_log, name)
    frames = read_log(burst_log)
    _, accepted = check_frames(frames)
    monitor = E2EMonitor()
    live = np.zeros(len(frames), dtype=bool)
    for row in range(len(frames)):
        status = monitor.check(int(frames.can_id[row]), bytes(frames.data[row, :frames.dlc[row]]),
                               timestamp_s=float(frames.timestamp_s[row]))
        live[row] = status in ("ok", "oksomelost")
    rows = np.array(sorted(verdicts))
    expected = np.array([verdicts[r] for r in rows.tolist()])
    after_gaps = int(np.count_nonzero(expected[1:] & expected[:-1]))
    assert after_gaps > 100  # the premise: many frames, bursts among them
    assert np.flatnonzero(accepted[rows] != expected).tolist() == []
    assert np.flatnonzero(live[rows] != expected).tolist() == []


def test_a_status_summary_held_behind_its_page_is_still_refused() -> None:
    """The window widened by the frames a cycle still refuses a stale frame: a summary held
    back 20 ms behind the page sent after it (its COUNTER one behind) is WRONG_SEQUENCE."""
    message = load_can_dbc(DBC).get_message_by_name("ODOM_STATUS")
    ids = [int(v) for v in dbc_attribute(message, "E2EDataIDs").split(",")]

    def status_frame(counter: int, page: int) -> bytes:
        data = bytearray(8)
        data[1] = counter | page << 4
        crc = cantools.autosar.compute_profile2_crc(bytes(data), ids[counter])
        assert crc is not None
        data[0] = crc
        return bytes(data)

    monitor = E2EMonitor()
    sent = [(0.0, 0, 0), (0.0, 1, 1), (0.1, 2, 0), (0.1, 3, 2), (0.2, 5, 3), (0.22, 4, 0)]
    statuses = [monitor.check(message.frame_id, status_frame(c, p), timestamp_s=t)
                for t, c, p in sent]
    assert statuses == ["ok", "ok", "ok", "ok", "oksomelost", "wrong_sequence"]
