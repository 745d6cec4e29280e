"""The live DISTANCE judge's allowance below the reference where the firmware merged steps: the
fine path over the union of the spans that may hold merged frames, each frame's path once, as
``distance.merged_path_m`` gives it to ``analyze`` (issue #11, rule 5: a PASS never hides a wrong
DISTANCE).

The spans (``livedistance.LiveDistance`` adds them): a stall's (the last twist judged before it
to the first after), a stall's before the first pose (``livefirst``), an ODOM_STATUS page's
whose ENC_E2E_LOST grew (the page before's latest frame to its own) and a span where ENC_E2E_OK
grew by more than ``skipdefect.MAX_RUN`` less than the host's frames (``liveskip``: from the page
before's latest frame to the frame after its own). A stall's frames lie in all three of the last
kinds at once: summed span by span (before), a 3 s stall mid-drive allowed 3.1 m below at the
first twist after it (5.1 m later) where ``analyze`` allows 1.6 m (1.8 m), so a DISTANCE 2.3 m
short PASSed the monitor and the bridge and FAILed ``analyze``
(``tests/test_live_distance_union.py``).

Frames are the tracker's numbers, paths the judge's exact int sums (2^-40 m) at them: they grow
with the frame, so the union of frame spans is the union of their path intervals. A span's end
may be a frame not heard yet (``liveskip``'s, the frame after a page): its path is taken when
that frame is fed (``on_frame``: one int compare a frame). At a twist naming frame e each span
(a, z] counts up to min(e, z), as ``merged_path_m`` clips it. A twist's allowance grows from
the last twist judged's by the union's path between their frames (``grown_units``), as
``analyze``'s cumulative allowance does between two samples: the earlier sample pinned DISTANCE
at its frame, so a span known only later (a page's, heard after the twists naming frames inside
it) adds only its frames after that twist's (before, the spans' whole path: 50 mm looser than
``analyze`` after this stall). Spans wholly below the last twist judged are dropped: a long
drive keeps a handful.
"""

from __future__ import annotations

from dataclasses import dataclass, field

NOT_WANTED = 1 << 62  # ``want`` when no span waits for its end's path


@dataclass
class MergedSpans:
    """The union's growth (module docstring). A span: (first frame a, path at a, last frame z,
    path at z or None until z is fed)."""

    _spans: list[tuple[int, int, int, int | None]] = field(default_factory=list)
    want: int = NOT_WANTED  # the first frame a span's end waits for

    def add(self, first: int, first_units: int, last: int, last_units: int | None) -> None:
        """The span (``first``, ``last``] of frames, the path at both (None: ``last`` not fed
        yet, taken by ``on_frame``)."""
        self._spans.append((first, first_units, last, last_units))
        if last_units is None:
            self.want = min(self.want, last)

    def on_frame(self, seq: int, units: int) -> None:
        """Frame ``seq`` fed (``seq >= want``), the path at it: the spans ending there (or
        before, a frame not numbered: looser) get it."""
        self._spans = [(a, ua, z, units if z <= seq and uz is None else uz)
                       for a, ua, z, uz in self._spans]
        pending = [z for _, _, z, uz in self._spans if uz is None]
        self.want = min(pending) if pending else NOT_WANTED

    def grown_units(self, since_units: int, e: int, e_units: int) -> int:
        """The union's path (2^-40 m) above ``since_units`` (the path at the last twist
        judged) up to a twist naming frame ``e`` (path ``e_units`` there): each span clipped at
        ``e`` (``distance.merged_path_m``'s rule); the spans wholly below dropped (no twist to
        come is judged from before ``since_units``)."""
        if not self._spans:  # a clean drive's twists
            return 0
        total, covered = 0, since_units
        for a, ua, z, uz in sorted(self._spans):
            if e <= a:
                continue
            top = e_units if e <= z or uz is None else uz
            total += max(top - max(ua, covered), 0)
            covered = max(covered, top)
        self._spans = [span for span in self._spans if span[3] is None or span[3] > since_units]
        return total
