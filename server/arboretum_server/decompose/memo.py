"""``ArrayMemo``: values remembered per numpy array while that array lives, keyed by its identity.

Refinement reuses work per lobe across calls: a lobe's plain tetrahedralisation and its carved shapes (by
its ``members`` array, ``carve``), a hull's packed faces (by its vertex array, ``clear``). numpy arrays are
not hashable, and a lobe's arrays are replaced, never changed in place, so the array's identity names the
lobe's state; a weak reference drops the entry when the array goes, so an id reused by a later array never
finds it.
"""

from __future__ import annotations

import weakref
from typing import Any

import numpy as np


class ArrayMemo:
    """A dict from live numpy arrays (by identity) to values; an entry goes with its array."""

    def __init__(self) -> None:
        self._store: dict[int, tuple[weakref.ref, Any]] = {}

    def get(self, array: np.ndarray) -> Any:
        """The value kept for this very ``array``, or None."""
        hit = self._store.get(id(array))
        return hit[1] if hit is not None and hit[0]() is array else None

    def put(self, array: np.ndarray, value: Any) -> Any:
        """Keep ``value`` for ``array`` while it lives; returns ``value``."""
        key = id(array)

        def forget(ref: weakref.ref, key: int = key) -> None:
            if self._store.get(key, (None,))[0] is ref:
                del self._store[key]

        self._store[key] = (weakref.ref(array, forget), value)
        return value

    def __contains__(self, key: int) -> bool:
        """Whether an entry is kept under the id ``key`` (for tests: it is gone once its array is)."""
        return key in self._store
