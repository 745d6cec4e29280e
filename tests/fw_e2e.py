"""The Python firmware's own E2E verdicts on WHEEL_ENCODERS (its receiver's statuses, which the
judges never see), and the host's E2E held against them: the host must take exactly the encoder
frames the firmware took."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from odocan.firmware import encoders as fw_encoders
from odocan.firmware.e2e import E2EStatus
from odocan.host.io.logs import read_log
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.protocol.decode import frame_keys
from odocan.host.protocol.e2e import check_frames, e2e_messages

TAKEN = (E2EStatus.OK, E2EStatus.OKSOMELOST)


@contextmanager
def firmware_verdicts() -> Iterator[list[bool]]:
    """Within: whether the Python firmware's E2E receiver took each WHEEL_ENCODERS frame it
    checked, in the order it checked them (the bus order)."""
    verdicts: list[bool] = []
    on_frame = fw_encoders.EncoderInput.on_frame

    def recorded(self: fw_encoders.EncoderInput, data: bytes) -> None:
        on_frame(self, data)
        verdicts.append(self.rx.status in TAKEN)

    with pytest.MonkeyPatch.context() as monkeypatch:
        monkeypatch.setattr(fw_encoders.EncoderInput, "on_frame", recorded)
        yield verdicts


def host_disagreements(log: Path, firmware: list[bool]
                       ) -> tuple[int, list[tuple[float, int]]]:
    """The log's WHEEL_ENCODERS frames (as many as ``firmware`` has verdicts), and (time s,
    COUNTER) of each the host's ``check_frames`` took where the firmware refused it, or the
    other way round."""
    frames = read_log(log)
    _, accepted = check_frames(frames)
    encoder = next(m for m in e2e_messages(default_plan()).values()
                   if m.name == "WHEEL_ENCODERS")
    at = np.flatnonzero(frame_keys(frames) == encoder.key)
    assert len(at) == len(firmware)
    wrong = [(round(float(frames.timestamp_s[i]), 4), int(frames.data[i, 1]) & 15)
             for i, took in zip(at.tolist(), firmware, strict=True) if bool(accepted[i]) != took]
    return len(at), wrong
