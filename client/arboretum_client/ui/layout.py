"""The 2D UI of one frame: the mode's panel and the status bar, drawn only when the state changes."""

from __future__ import annotations

from arboretum_client.net import JobStatus
from arboretum_client.tools.state import REFINEMENT, ClientState

from . import library_panel, refine_panel, status_bar
from .widgets import Canvas


def draw_ui(size: tuple[int, int], state: ClientState, jobs: dict[int, JobStatus]) -> Canvas:
    """A canvas of the output size with the panels for ``state`` (and the job progress bars)."""
    c = Canvas(size)
    (refine_panel if state.mode == REFINEMENT else library_panel).draw(c, state)
    status_bar.draw(c, state, jobs)
    return c


def ui_key(state: ClientState, jobs: dict[int, JobStatus]) -> tuple:
    """Changes whenever the UI image must be redrawn."""
    return (state.ui_version, tuple((k, j.fraction, j.message) for k, j in jobs.items()))
