"""A tick's frames at once: the ``DataFrame`` tuples the ``odocan`` transport queues for the
lockstep rig (``sim.transport``: ``OdocanBus.send_data``, ``drain``) and the listeners that take
them in a batch (``FrameBatchListener``: ``host.io.frames.FrameCollector``; ``sim.tickloop``
hands them out). A module of its own, light to import: the host's log reader needs the listener
class, not the transport."""

from __future__ import annotations

import can
from can import Message

# A classic 11-bit data frame as ``send_data`` queues it: (timestamp s, identifier, payload).
# Immutable, so one tuple serves every receiver; ``recv`` turns it into a fresh ``Message``.
DataFrame = tuple[float, int, bytes]
Received = DataFrame | Message  # what ``sim.transport.OdocanBus.drain`` returns, in bus order


class FrameBatchListener(can.Listener):
    """A python-can ``Listener`` that also takes a tick's frames at once, as ``OdocanBus.drain``
    returns them (``sim.tickloop.deliver`` hands them so when every listener is one): the same
    frames in the same order as ``on_message_received`` one by one, without a ``Message`` per
    ``DataFrame``. A ``Message`` in the batch belongs to the listener (the receiver's own copy);
    no one changes it afterwards.

    ``passive`` (a class attribute, False here): the listener only keeps what it hears, sending
    nothing and read by no one while a rig runs; ``sim.tickloop.TickLoop.run`` may then hand it
    the frames once per simulated second instead of every tick (the same frames, in the same
    order, in bigger batches; all of them before a progress call and when the run ends)."""

    passive = False

    def on_frames(self, frames: list[Received]) -> None:
        """The frames, in bus order (the list may be kept: the caller does not reuse it)."""
        raise NotImplementedError
