"""One context-manager base for everything that holds a resource released by ``close()``.

Drivers' sources and the recorder inherit it, so ``with source:`` closes the link and
``with recorder:`` closes the store, even when the block raises.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from types import TracebackType
from typing import Self


class Closing(ABC):
    """Context manager that calls :meth:`close` on exit (idempotent ``close`` expected)."""

    @abstractmethod
    def close(self) -> None:
        """Release the resource; idempotent."""

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
