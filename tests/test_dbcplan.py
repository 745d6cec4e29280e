"""The DBC plan (``host.protocol.dbcplan``): what ``odocan analyze`` reads of the DBC without
cantools at run time must decode every frame as cantools does, and its cache must follow the DBC.

The reference is cantools itself, one frame at a time (``Database.decode_message``, raw values):
random payloads of every message of odocan's DBC, decoded by the bulk decoder from a plan that
went through its JSON cache file."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from odocan.host.io.frames import FrameArrays
from odocan.host.protocol.dbcplan import (
    DbcPlan,
    cache_dir,
    load_plan,
    plan_from_json,
    plan_key,
    plan_of,
    plan_to_json,
)
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import e2e_messages
from odocan.sim import contract
from odocan.sim.contract import DBC_PATH, database

FRAMES_PER_MESSAGE = 300


def _cached_plan(directory: Path) -> DbcPlan:
    """odocan's DBC planned into ``directory`` and read back from the cache file."""
    load_plan(DBC_PATH, directory)
    (cached,) = directory.glob("dbc-*.json")
    plan = load_plan(DBC_PATH, directory)
    assert plan == plan_from_json(cached.read_text(encoding="utf-8"), plan_key(
        DBC_PATH.read_bytes()))
    return plan


def _random_frames(rng: np.random.Generator) -> FrameArrays:
    """``FRAMES_PER_MESSAGE`` frames of random payload for every message of the DBC, mixed."""
    messages = database().messages
    ids = np.repeat([m.frame_id for m in messages], FRAMES_PER_MESSAGE)
    order = rng.permutation(len(ids))
    n = len(ids)
    return FrameArrays(
        timestamp_s=np.arange(n, dtype=np.float64) * 1e-3,
        can_id=ids[order].astype(np.uint32),
        dlc=np.full(n, 8, dtype=np.uint8),
        data=rng.integers(0, 256, size=(n, 8), dtype=np.uint8),
        flags=np.zeros(n, dtype=np.uint8),
    )


def test_the_cached_plan_decodes_every_signal_as_cantools(tmp_path: Path) -> None:
    plan = _cached_plan(tmp_path)
    frames = _random_frames(np.random.default_rng(14))
    decoder = BulkDecoder(plan)
    db = database()
    for message in db.messages:
        muxes = [s for s in message.signals if s.is_multiplexer and s.multiplexer_signal is None]
        pages = sorted({i for s in message.signals for i in (s.multiplexer_ids or ())})
        groups = [decoder.decode_page(frames, message.name, p) for p in pages] if muxes else [
            decoder.decode(frames, message.name)]
        decoded = set()
        for group in groups:
            for row, position in enumerate(group["index"].tolist()):
                expected = db.decode_message(message.frame_id, bytes(frames.data[position]),
                                             decode_choices=False, scaling=False)
                got = {k: v[row] for k, v in group.items() if k not in ("index", "timestamp_s")}
                assert got == expected, (message.name, position)
                decoded.add(position)
        assert decoded == _paged(frames, message.frame_id, muxes[0].name if muxes else None,
                                 pages), message.name


def _paged(frames: FrameArrays, frame_id: int, mux: str | None, pages: list[int]) -> set[int]:
    """Positions of the frames of ``frame_id`` (of a multiplexed message: those whose
    multiplexer value, as cantools reads it, selects one of its ``pages``)."""
    db, found = database(), set()
    for position in np.flatnonzero(frames.can_id == frame_id).tolist():
        try:
            values = db.decode_message(frame_id, bytes(frames.data[position]), scaling=False,
                                       decode_choices=False)
        except Exception:  # cantools: a multiplexer value of no page
            continue
        assert isinstance(values, dict)
        if mux is None or values[mux] in set(pages):
            found.add(position)
    return found


def test_the_plan_carries_what_the_judge_reads(tmp_path: Path) -> None:
    plan, db = _cached_plan(tmp_path), database()
    assert e2e_messages(plan) == e2e_messages(db)  # IDs, lengths, data IDs, cycle times
    assert [m.name for m in plan.messages] == [m.name for m in db.messages]
    for ours, theirs in zip(plan.messages, db.messages, strict=True):
        assert (ours.send_type, ours.cycle_time) == (theirs.send_type, theirs.cycle_time)
        for signal in theirs.signals:
            mine = ours.get_signal_by_name(signal.name)
            assert (mine.scale, mine.offset) == (signal.scale, signal.offset)
            assert mine.choices == (None if signal.choices is None else {
                int(k): str(v) for k, v in signal.choices.items()})
    with pytest.raises(KeyError):
        plan.get_message_by_name("NO_SUCH_MESSAGE")
    with pytest.raises(KeyError):
        plan.messages[0].get_signal_by_name("NO_SUCH_SIGNAL")


def test_an_edited_dbc_is_read_again(tmp_path: Path) -> None:
    dbc = tmp_path / "edited.dbc"
    text = DBC_PATH.read_text(encoding="utf-8")
    dbc.write_text(text, encoding="utf-8")
    cache = tmp_path / "cache"
    assert load_plan(dbc, cache).get_message_by_name("WHEEL_ENCODERS").cycle_time == 10
    edited = text.replace('BA_ "GenMsgCycleTime" BO_ 256 10;', 'BA_ "GenMsgCycleTime" BO_ 256 25;')
    assert edited != text
    dbc.write_text(edited, encoding="utf-8")  # same path, same size class: the content decides
    assert load_plan(dbc, cache).get_message_by_name("WHEEL_ENCODERS").cycle_time == 25
    assert len(list(cache.glob("dbc-*.json"))) == 2


def test_a_damaged_cache_is_derived_again_and_rewritten(tmp_path: Path) -> None:
    expected = plan_of(database())
    assert load_plan(DBC_PATH, tmp_path) == expected
    (cached,) = tmp_path.glob("dbc-*.json")
    for damage in ("{not json", json.dumps({"key": "another DBC", "messages": []}), "[]",
                   json.dumps({"key": plan_key(DBC_PATH.read_bytes()), "messages": [{}]})):
        cached.write_text(damage, encoding="utf-8")
        assert load_plan(DBC_PATH, tmp_path) == expected
        assert plan_from_json(cached.read_text(encoding="utf-8"),
                              plan_key(DBC_PATH.read_bytes())) == expected


def test_a_cache_that_cannot_be_written_costs_only_the_speed(tmp_path: Path) -> None:
    blocked = tmp_path / "a-file"
    blocked.write_text("not a directory", encoding="utf-8")
    assert load_plan(DBC_PATH, blocked / "cache") == plan_of(database())
    assert blocked.read_text(encoding="utf-8") == "not a directory"


def test_the_json_round_trip_is_exact() -> None:
    plan = plan_of(database())
    key = plan_key(DBC_PATH.read_bytes())
    assert plan_from_json(plan_to_json(plan, key), key) == plan
    assert plan_from_json(plan_to_json(plan, key), key + "x") is None


def test_the_cache_directory_follows_the_environment(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("ODOCAN_CACHE_DIR", str(tmp_path / "mine"))
    assert cache_dir() == tmp_path / "mine"
    monkeypatch.delenv("ODOCAN_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_dir() == tmp_path / "xdg" / "odocan"


WARM_PROBE = """
import json, sys
from odocan.host.protocol.dbcplan import default_plan
default_plan()
print(json.dumps(sorted({m.split(".")[0] for m in sys.modules})))
"""


def test_a_warm_cache_needs_neither_cantools_nor_python_can(tmp_path: Path) -> None:
    """The first process derives the plan with cantools; the next one reads it alone."""
    env = dict(os.environ, ODOCAN_CACHE_DIR=str(tmp_path))
    runs = [subprocess.run([sys.executable, "-c", WARM_PROBE], capture_output=True, text=True,
                           env=env, timeout=300, check=True) for _ in range(2)]
    cold, warm = (set(json.loads(r.stdout.strip().splitlines()[-1])) for r in runs)
    assert "cantools" in cold  # the probe sees cantools when it is used
    assert warm.isdisjoint({"cantools", "can"}), sorted(warm & {"cantools", "can"})


def test_the_rig_reads_each_cycle_time_from_the_plan_as_cantools_gives_it() -> None:
    """``odocan run`` builds its rig under ``contract.read_as(plan)``: every cyclic message's
    cycle time (the sim's send periods) is the one cantools reads from the DBC, and the plan is
    what is read there (a message the plan lacks is not found), cantools again after it."""
    names = [m.name for m in database().messages if m.cycle_time]
    assert {"MOTOR_CMD", "SIM_TRUTH"} <= set(names)
    by_cantools = {name: contract.cycle_time_s(name) for name in names}
    plan = load_plan(DBC_PATH)
    with contract.read_as(plan):
        assert {name: contract.cycle_time_s(name) for name in names} == by_cantools
        with contract.read_as(DbcPlan(())), pytest.raises(KeyError):
            contract.cycle_time_s("MOTOR_CMD")
    assert contract.cycle_time_s("MOTOR_CMD") == by_cantools["MOTOR_CMD"]
