"""``Closing``: a context manager whose exit calls ``close()`` (rigs, fleets, sessions)."""

from __future__ import annotations

from typing import Self


class Closing:
    """Subclasses implement ``close()``; ``with obj:`` closes it on the way out, error or not."""

    def close(self) -> None:
        """Release what the object holds (buses, listeners)."""
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
