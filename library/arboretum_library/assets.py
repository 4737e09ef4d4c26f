"""The one place that finds bundled assets (sample scans, textures, module sets).

Set ``ARBORETUM_ASSETS`` to use another folder; by default the repository's ``assets/``.
"""

from __future__ import annotations

import os
from pathlib import Path

from .errors import InputError


def assets_dir() -> Path:
    """The assets folder."""
    env = os.environ.get("ARBORETUM_ASSETS")
    return Path(env) if env else Path(__file__).resolve().parents[2] / "assets"


def asset_path(*parts: str) -> Path:
    """Path of a bundled asset; raises ``InputError`` naming it when it is not there."""
    path = assets_dir().joinpath(*parts)
    if not path.exists():
        raise InputError(f"bundled asset {'/'.join(parts)} is missing (looked in {assets_dir()})")
    return path


def sample_scans() -> list[Path]:
    """The bundled real scans (``assets/scans/*/*.xyz``), sorted by name."""
    return sorted((assets_dir() / "scans").glob("*/*.xyz"))
