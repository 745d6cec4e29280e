"""``Closing``: a context manager whose exit calls ``close()`` (rigs, fleets, sessions), and
``release_all``, what such a ``close()`` does with many things to release."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Self


def release_all(releases: Iterable[Callable[[], object]]) -> None:
    """Call every one of ``releases`` (listeners' ``stop``, buses' ``shutdown``), even when one
    fails (e.g. a log that cannot be finished on a full disk); the first error is raised once
    all have run."""
    first: BaseException | None = None
    for release in releases:
        try:
            release()
        except Exception as exc:
            first = first or exc
    if first is not None:
        raise first


class Closing:
    """Subclasses implement ``close()``; ``with obj:`` closes it on the way out, error or not."""

    def close(self) -> None:
        """Release what the object holds (buses, listeners)."""
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
