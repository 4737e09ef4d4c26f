"""YAML 1.2 numbers for PyYAML's safe loader, shared by every command that reads YAML scripts.

PyYAML follows YAML 1.1, whose float pattern needs a dot and a signed exponent: ``1e-3``, ``1E5`` and
``1e300`` are read as text there, so ``scale: 1e-3`` in a script would be refused as "not a number".
YAML 1.2 (core schema) reads them as numbers. This module holds the pattern and adds it to a loader
class; it does not import PyYAML itself (the library layer stays free of it), the caller passes the class.
"""

from __future__ import annotations

import functools
import re

EXPONENT_FLOAT = re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$")
"""Plain scalars that YAML 1.2 reads as floats and YAML 1.1 as text: a mantissa, then an exponent."""

FIRST_CHARACTERS = list("-+0123456789.")
"""The characters such a scalar can start with (PyYAML indexes implicit resolvers by first character)."""


@functools.cache
def with_yaml12_numbers(safe_loader: type) -> type:
    """A subclass of ``safe_loader`` (``yaml.SafeLoader``) that also reads ``EXPONENT_FLOAT`` scalars as
    floats; ``safe_loader`` itself is left unchanged."""
    loader = type("Yaml12SafeLoader", (safe_loader,), {})
    loader.add_implicit_resolver("tag:yaml.org,2002:float", EXPONENT_FLOAT, FIRST_CHARACTERS)  # type: ignore[attr-defined]
    return loader
