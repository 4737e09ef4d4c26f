"""Checks of a command's arguments, made before any work: one ``InputError`` naming the option.

Shared by the commands of the server and the client (``outputs.check_output`` checks output paths).
"""

from __future__ import annotations

import math
from pathlib import Path

from .errors import InputError


def check_seed(seed: int, what: str = "--seed") -> None:
    """``InputError`` unless ``seed`` is a non-negative integer (what numpy's generators take)."""
    if seed < 0:
        raise InputError(f"{what} must not be negative, got {seed}")


def check_species(species: str | None) -> None:
    """``InputError`` for a ``--species`` given blank ("" or spaces): not a species, and the two commands
    that take it read it differently (``decompose`` stored ``''``, ``library build`` guessed from the file
    name, session 18). Left out, each command has its default."""
    if species is not None and not species.strip():
        raise InputError(f"--species must name a species (or be left out), got {species!r}")


def check_height(height: float) -> None:
    """``InputError`` for a ``--height`` that is not finite, negative (0 keeps the scan's units: both
    ``decompose`` and, since session 18, ``library build``) or beyond ``pointio.MAX_COORDINATE`` (the
    decomposition options' limit)."""
    from .pointio import MAX_COORDINATE

    if not (math.isfinite(height) and height >= 0):
        raise InputError(f"--height must be a finite number >= 0 (0: keep the scan's units), got {height}")
    if height > MAX_COORDINATE:
        raise InputError(f"--height must be at most {MAX_COORDINATE:g} (metres), got {height:g}")


def check_input_file(path: str, what: str) -> Path:
    """``path`` as a Path when it names an existing file; ``InputError`` naming ``what`` otherwise."""
    p = Path(path)
    if p.is_dir():
        raise InputError(f"{what} {p}: is a folder, not a file")
    if not p.is_file():
        raise InputError(f"{what} {p}: no such file")
    return p


def check_number(value: float | None, what: str, lo: float, hi: float, lo_open: bool = False) -> None:
    """``InputError`` unless ``value`` (None: the default) is a finite number in [lo, hi] ((lo, hi]
    when ``lo_open``); ``hi`` may be ``math.inf`` (no upper bound: the message then asks for a finite
    number, never for one "<= inf")."""
    if value is None:
        return
    low_ok = value > lo if lo_open else value >= lo
    if not (math.isfinite(value) and low_ok and value <= hi):
        low = f"> {lo:g}" if lo_open else f">= {lo:g}"
        high = f"<= {hi:g}" if math.isfinite(hi) else "finite"
        raise InputError(f"{what} must be a number {low} and {high}, got {value}")
