"""Save and load an HBL (.npz via ``arboretum_library.codec.save_record`` / ``load_record``).

Kept as the grow command's named entry points; the format is the library's record file, so an HBL
saved by ``arboretum decompose --save-hbl`` grows as it is.
"""

from __future__ import annotations

import os

from arboretum_library.codec import load_record, save_record
from arboretum_library.model import HBL


def save_hbl(path: str | os.PathLike, hbl: HBL) -> None:
    """Write ``hbl`` to ``path`` (.npz, no pickles), atomically."""
    save_record(path, hbl)


def load_hbl(path: str | os.PathLike) -> HBL:
    """Read an HBL; a missing, malformed or non-HBL file raises ``InputError`` naming it."""
    return load_record(path, HBL)
