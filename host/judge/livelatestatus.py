"""An ODOM_STATUS frame the bus held back behind later sends of the same firmware: no reboot.

A reboot is told by a summary whose UPTIME goes back, or that says INIT after running
(``host.judge.sources.SourceWatch``). A summary the bus held back (``--faults delay``, a loaded
bus, a gateway's queue) behind later ODOM_STATUS frames of the same firmware says the UPTIME and
the state it had when it was sent: an UPTIME below the latest heard when a second turned
meanwhile. Issue #11: kobuki, seed 2, ``delay=0.5:100``: the summary of COUNTER 2 (UPTIME 0),
sent at 0.90 s, came at 1.00 s after COUNTER 4 and 5 (UPTIME 1) and was told a reboot; the
reference restarted from a power-up pose that the firmware never had, and a pose 10 mm off from
2.0 s PASSed (``tests/test_combo_faults.py``).

Such a frame fills a hole of its sender's sequence: its COUNTER is 1 to ``HELD_BACK_MAX`` steps
behind the latest in-order frame's, and no in-order frame of the last ``RECENT`` carried it (the
bus sent it late, so none came in its place on time). A new firmware restarts its COUNTERs at 0
(E2E Profile 2; ``bootticks``): its frames come after the old firmware's last, so a COUNTER of
it that lies behind the old one's latest repeats one the old firmware sent within the last lap,
which the bus carried unless it lost it too. So a frame that fills a hole is told held back;
one that repeats a COUNTER heard in order is not (a reboot stays one). A hole is filled once: a
frame whose COUNTER a held-back frame already filled repeats it too (kobuki square 655,
``stall=2.9:0.2,reboot=6.2:0.2,delay=0.1:20``: the old firmware's COUNTER 0 came late, after 1;
the new firmware's boot summary, COUNTER 0 after the old 7, was taken for a held-back frame, the
reboot told 120 ms late at its next summary (fitted), and the correct firmware FAILed 837.6 mm:
``tests/test_mcu_bus_combos.py``). Known limit: a reboot
whose first frames the bus lost, whose next COUNTER is one the old firmware's last frames also
lost, is told at its next summary (a cycle later), which continues the new sequence.

One rule for every judge: the whole log (``held_back``), the streamed ``analyze`` (a
``StatusOrder`` carried across chunks) and the live ones (``SourceWatch.hear_status``).
"""

from __future__ import annotations

from collections.abc import Iterable

from odocan.host.protocol.busfacts import ENC_COUNTER_LAP, ENC_COUNTER_MASK

RECENT = ENC_COUNTER_LAP // 2  # in-order frames kept: half a lap (ODOM_STATUS: 400 ms)
HELD_BACK_MAX = RECENT - 1  # steps behind the latest in order a held-back frame may lie


Summary = tuple[int, str]  # a summary's UPTIME (s) and STATE name


class StatusOrder:
    """One sender's ODOM_STATUS frames (CRC holding, any page, bus order): which were held back
    behind later sends of it, and which held-back summaries say nothing of a reboot (module
    docstring)."""

    top: int  # the latest in-order frame's COUNTER (-1: none yet)
    recent: list[int]  # the COUNTERs of the latest ``RECENT`` in-order frames, oldest first
    said: list[Summary | None]  # what each of them said, a summary (None: another page)
    filled: list[int]  # the COUNTERs of the held-back frames heard behind ``top`` (holes filled)
    late: bool  # whether the frame heard last was held back
    prior: Summary | None  # then: the summary sent last before it (in-order, COUNTER behind)

    def __init__(self) -> None:
        self.top = -1
        self.recent = []
        self.said = []
        self.filled = []
        self.late = False
        self.prior = None

    def copy(self) -> StatusOrder:
        """A copy that hears on without changing this one (a stream chunk's reading leaves
        the order it carried as it was)."""
        out = StatusOrder()
        out.top, out.recent, out.said = self.top, list(self.recent), list(self.said)
        out.filled, out.late, out.prior = list(self.filled), self.late, self.prior
        return out

    def hear(self, counter: int) -> bool:
        """One frame's E2E ``counter``: whether it was held back (kept in ``late``)."""
        behind = (self.top - counter) & ENC_COUNTER_MASK
        late = (self.top >= 0 and 0 < behind <= HELD_BACK_MAX and counter not in self.recent
                and counter not in self.filled)
        self.late, self.prior = late, None
        if late:
            self.filled.append(counter)
            nearest = RECENT
            for c, said in zip(self.recent, self.said, strict=True):
                ahead = (counter - c) & ENC_COUNTER_MASK
                if said is not None and 0 < ahead < nearest:
                    nearest, self.prior = ahead, said
            return True
        self.top = counter
        if self.filled:  # (none, the usual frame: no list made)
            self.filled = [c for c in self.filled  # holes still behind it
                           if 0 < (counter - c) & ENC_COUNTER_MASK <= HELD_BACK_MAX]
        recent, sayings = self.recent, self.said  # the latest ``RECENT``, in place (per frame)
        recent.append(counter)
        sayings.append(None)
        if len(recent) > RECENT:
            del recent[0], sayings[0]
        return False

    def passed_over(self, uptime_s: int, state: str) -> bool:
        """The frame heard last is a summary (UPTIME, STATE): whether it was held back and says
        nothing of a reboot against the summary its firmware sent before it (no UPTIME below
        that one's, no INIT after running); none known before it: nothing said either. An
        in-order summary is kept for the held-back ones after it."""
        if not self.late:
            if self.said:
                self.said[-1] = (uptime_s, state)
            return False
        prior = self.prior
        return prior is None or not (
            uptime_s < prior[0] or (state == "INIT" and prior[1] not in ("", "INIT")))

    def hear_all(self, counters: Iterable[int], said: Iterable[Summary | None]) -> list[bool]:
        """``hear`` of each of ``counters`` in order, then ``passed_over`` of each that is a
        summary (``said``: its UPTIME and STATE; None: another page): which summaries to pass
        over."""
        over = []
        for counter, summary in zip(counters, said, strict=True):
            self.hear(int(counter))
            over.append(summary is not None and self.passed_over(*summary))
        return over


def held_back(counters: Iterable[int], said: Iterable[Summary | None]) -> list[bool]:
    """``StatusOrder.hear_all`` of one sender's ODOM_STATUS frames (bus order)."""
    return StatusOrder().hear_all(counters, said)
