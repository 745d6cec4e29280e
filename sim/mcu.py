"""Facts of the modelled MCU that the judges reason with too, in a module light to import (the
board, ``sim.board``, brings python-can and the firmware; ``odocan analyze`` needs neither)."""

from __future__ import annotations

HW_RX_FIFO_FRAMES = 3  # the CAN controller's receive FIFO depth (bxCAN: 3 per FIFO)
