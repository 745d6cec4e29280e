"""The resend alias time rule stands in one place (``host.judge.resendalias.aged_past_alias``):
a pose half heard ``ALIAS_CYCLES`` encoder cycles or more after the frame it was matched to, or
at an unknown time, may name a later frame with that COUNTER, so it is judged as no resend.

``analyze``'s resent poses (``resendalias.may_alias``), the live judge's
(``liveresent.may_alias_live``) and the DISTANCE judge's resends (``distance.DistanceJudge.take``)
each compared the time with ``ALIAS_CYCLES`` cycles themselves, three copies of one rule that a
change to one would have left the others behind. Checked on the rule (its edge, NaN) and on the
source: no other judge module compares against ``ALIAS_CYCLES`` itself."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from odocan.host.judge import resendalias
from odocan.host.judge.resendalias import ALIAS_CYCLES, aged_past_alias

JUDGE = Path(resendalias.__file__).resolve().parent
CYCLE_S = 0.01


def test_the_rule_at_its_edge_and_for_an_unknown_time() -> None:
    edge_s = ALIAS_CYCLES * CYCLE_S
    assert not aged_past_alias(edge_s - 1e-6, CYCLE_S)
    assert aged_past_alias(edge_s, CYCLE_S)
    assert aged_past_alias(math.nan, CYCLE_S)  # a frame of unknown time may be aliased
    since = np.array([0.0, edge_s - 1e-6, edge_s, 1.0, math.nan])
    assert aged_past_alias(since, CYCLE_S).tolist() == [False, False, True, True, True]


def test_every_judge_takes_the_rule_from_resendalias() -> None:
    users = {"resendalias.py", "liveresent.py", "distance.py"}
    copies = sorted(p.name for p in JUDGE.glob("*.py")
                    if p.name != "resendalias.py" and "ALIAS_CYCLES" in p.read_text())
    assert copies == [], f"the alias time rule restated in {copies}"
    callers = {p.name for p in JUDGE.glob("*.py")
               if re.search(r"\baged_past_alias\(", p.read_text())}
    assert callers == users
