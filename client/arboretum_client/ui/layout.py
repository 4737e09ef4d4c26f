"""The 2D UI of one frame: the mode's panel and the status bar, drawn only when the state changes.

The layout degrades with the output size instead of failing: the side panel narrows to the width there
is (and is left out below ``MIN_PANEL`` pixels), the library list shows the rows that fit above the
status bar, and the status bar drops its progress bars and right-hand legend when they do not fit.
"""

from __future__ import annotations

from arboretum_client.net import JobStatus
from arboretum_client.tools.state import REFINEMENT, ClientState

from . import library_panel, refine_panel, status_bar
from .widgets import PANEL_W, PANEL_X, Canvas

MIN_PANEL = 150
"""Narrower than this (or an output less than ``MIN_PANEL`` pixels high) and there is no side panel."""


def panel_width(size: tuple[int, int]) -> int:
    """The side panel's width for an output of ``size`` pixels (0: no panel)."""
    w = min(PANEL_W, size[0] - 2 * PANEL_X)
    return w if w >= MIN_PANEL and size[1] >= MIN_PANEL else 0


def draw_ui(size: tuple[int, int], state: ClientState, jobs: dict[int, JobStatus]) -> Canvas:
    """A canvas of the output size with the panels for ``state`` (and the job progress bars)."""
    c = Canvas(size)
    width = panel_width(size)
    if width:
        bottom = size[1] - status_bar.height(size[1], jobs) - PANEL_X  # the panel ends above the status bar
        (refine_panel if state.mode == REFINEMENT else library_panel).draw(c, state, width, bottom)
    status_bar.draw(c, state, jobs)
    return c


def ui_key(state: ClientState, jobs: dict[int, JobStatus]) -> tuple:
    """Changes whenever the UI image must be redrawn."""
    return (state.ui_version, tuple((k, j.fraction, j.message) for k, j in jobs.items()))
