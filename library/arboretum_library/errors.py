"""One exception type per layer, each carrying a message meant for a user.

The CLI prints ``str(error)`` as one line and exits non-zero; the server turns it into an error reply
with ``code``. Anything that is not an ``ArboretumError`` is a bug and keeps its traceback.
"""

from __future__ import annotations


class ArboretumError(Exception):
    """Base of every error a user can cause. ``str(e)`` is a complete, single-line message."""

    code = "error"


class InputError(ArboretumError):
    """A file or argument the user gave is missing, malformed or unusable."""

    code = "bad_input"


class ValidationError(ArboretumError):
    """A record was built with values that break its invariants (shape, finiteness, indices)."""

    code = "invalid_record"


class StoreError(ArboretumError):
    """The example library on disk cannot do what was asked (missing example, broken folder)."""

    code = "store"


class ProtocolError(ArboretumError):
    """A wire message is malformed, too large, or of another protocol version."""

    code = "protocol"
