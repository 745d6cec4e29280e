"""The streamed analysis' refusal (``host.judge.stream_analysis``), in a module of its own."""

from __future__ import annotations

from odocan.sim.exceptions import OdocanError


class NotStreamable(OdocanError):
    """The streamed report could differ from the whole log's: analyse the whole log instead.
    A life is refused when its frames' times go back where the stall detection looks
    (``StreamStalls.exact``), when a pose, twist or encoder frame came in a burst after a busy
    bus (``samples.queued_frames``: their pairing takes a median over the whole life), when a
    resent pose differs from the first naming its encoder frame (``host.judge.resent``: the
    sample may have been given out chunks before), or when encoder frames were settled from
    the poses and pages after them near a chunk's edge, the evidence horizon exceeded
    (``stream_e2e.StreamE2E.exact``, ``stream_carry``)."""


UNSETTLED = ("a starved or jittered recorder's stamps: encoder frames settled from the poses "
             "and pages after them, beyond the evidence horizon the stream carries "
             "(stream_carry.MAX_CARRY_S)")


class NamesAhead(NotStreamable):
    """A pose names an encoder frame after those heard before it (``aheadnamed``): judged at
    the frames it may name, which the whole log's judge reads around it."""


AHEAD = "a pose naming an encoder frame after those heard before it"
