"""What every handler is given: the sessions, the example library and the server's options."""

from __future__ import annotations

import logging
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path

from arboretum_library.errors import InputError, StoreError
from arboretum_library.model import Example
from arboretum_library.store import Library
from arboretum_library.store_lock import LibraryGone, check_present
from arboretum_server.assembly.recombine import RecombineOptions

from .sessions import Sessions

log = logging.getLogger(__name__)

EXAMPLE_CACHE = 256
LOCK_TIMEOUT_S = 1.0
"""How long the loop thread waits for another process's library write lock before answering ``busy``."""


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
    lock_timeout: float = LOCK_TIMEOUT_S
    """Seconds a library write (or the first open, which reconciles) waits for another writer."""
    _library: Library | None = None
    _examples: OrderedDict = field(default_factory=OrderedDict)

    def library(self) -> Library:
        """The example library (opened on first use; created if missing). ``StoreError`` once it is gone
        (deleted, moved, unmounted): never made anew behind the sessions' backs, which name its examples."""
        if self.library_path is None:
            raise InputError("this server has no example library (start it with --library LIB)")
        if self._library is not None:
            try:
                check_present(Path(self.library_path))
            except LibraryGone:  # said for the server, whose restart is the way to a new library
                raise StoreError(f"library {self.library_path} is gone (deleted while the server ran?); put it "
                                 "back, or restart the server to start a new one") from None
        if self._library is None:
            self._library = Library.open(self.library_path, create=True, lock_timeout=self.lock_timeout)
            r = self._library.recovered
            if r.catalog_problem:
                log.warning("the catalog of %s %s: rebuilt it from the example folders (old file: %s)",
                            self.library_path, r.catalog_problem, r.catalog_kept or "none")
        return self._library

    def example(self, example_id: str) -> Example:
        """Library example ``example_id``, cached by its revision (another process may replace or delete
        it: each call checks the revision, a read of its small meta.json, and reloads when it changed)."""
        lib = self.library()
        revision = lib.revision(example_id)
        hit = self._examples.get(example_id)
        if hit is not None and hit[0] == revision:
            self._examples.move_to_end(example_id)
            return hit[1]
        ex = lib.get(example_id)
        self._examples[example_id] = (revision, ex)
        self._examples.move_to_end(example_id)
        if len(self._examples) > EXAMPLE_CACHE:
            self._examples.popitem(last=False)
        return ex

    def forget(self, example_id: str) -> None:
        self._examples.pop(example_id, None)

    def close(self) -> None:
        if self._library is not None:
            self._library.close()
            self._library = None
