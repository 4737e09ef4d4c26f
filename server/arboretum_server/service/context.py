"""What every handler is given: the sessions, the example library and the server's options."""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path

from arboretum_library.errors import InputError
from arboretum_library.model import Example
from arboretum_library.store import Library
from arboretum_server.assembly.recombine import RecombineOptions

from .sessions import Sessions

EXAMPLE_CACHE = 256


@dataclass
class Context:
    """Server state shared by the handlers (used from the server's one loop thread)."""

    sessions: Sessions
    library_path: Path | None = None
    recombine: RecombineOptions = field(default_factory=RecombineOptions)
    operations: tuple[str, ...] = ()
    """Request types the dispatcher handles (for the handshake)."""
    warming: bool = False
    """True while the warm-up thread imports the heavy modules (set and cleared by ``arboretum serve``)."""
    _library: Library | None = None
    _examples: OrderedDict = field(default_factory=OrderedDict)

    def library(self) -> Library:
        """The example library (opened on first use; created if missing)."""
        if self.library_path is None:
            raise InputError("this server has no example library (start it with --library LIB)")
        if self._library is None:
            self._library = Library.open(self.library_path, create=True)
        return self._library

    def example(self, example_id: str) -> Example:
        """Library example ``example_id`` (cached; examples never change under an id but by delete)."""
        ex = self._examples.get(example_id)
        if ex is None:
            ex = self.library().get(example_id)
            self._examples[example_id] = ex
            if len(self._examples) > EXAMPLE_CACHE:
                self._examples.popitem(last=False)
        else:
            self._examples.move_to_end(example_id)
        return ex

    def forget(self, example_id: str) -> None:
        self._examples.pop(example_id, None)

    def close(self) -> None:
        if self._library is not None:
            self._library.close()
            self._library = None
