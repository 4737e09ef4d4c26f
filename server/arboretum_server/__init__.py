"""arboretum_server."""

from pathlib import Path

from . import jitcache

jitcache.use(Path(__file__).parent)  # before any kernel module: numba misses edits in other files otherwise
