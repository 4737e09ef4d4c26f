"""The client's state: plain data, owned by the main thread, changed by tools and by network replies.

Nothing here touches GL or sockets. ``scene_version`` changes whenever what is drawn changes (the frame
loop rebuilds and re-uploads the scene then, never per frame); ``ui_version`` whenever a panel must be
redrawn.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from arboretum_library.assembly import Assembly
from arboretum_library.model import HBL, Example
from arboretum_library.protocol import GrownTree, RefineCloud

MODELING, REFINEMENT = "modeling", "refinement"


@dataclass
class ClientState:
    mode: str = MODELING
    """'modeling' (assemble examples) or 'refinement' (fix a decomposition), VRTree 3.3."""
    # library browser
    library: list[dict] = field(default_factory=list)
    """Catalog rows shown in the browser (a listing or search hits, best first)."""
    query: str = ""
    search_focus: bool = False
    tag_filter: str = ""
    """'' or one tag the listing is filtered by."""
    chosen: str | None = None
    """Library example id the next ``select`` on empty space places."""
    examples: dict[str, Example] = field(default_factory=dict)
    """Cache of fetched examples by id (sketched examples included)."""
    # modeling
    assembly: Assembly = field(default_factory=Assembly)
    revision: int = 0
    can_undo: bool = False
    can_redo: bool = False
    selection: list[str] = field(default_factory=list)
    """Pick names selected: 'inst:NAME' or 'inst:NAME/lobe:J' (modeling), 'lobe:J' (refinement)."""
    show_all: bool = True
    """Show all examples (True) or only the selected one (modeling) / the focused one (refinement)."""
    focus: int = 0
    """Refinement 'show one': index of the main branch (example) shown."""
    density: float = 1.0
    """Twig and leaf density for growth (1 = the server's default)."""
    grown: GrownTree | None = None
    merged_flash: dict[str, float] = field(default_factory=dict)
    """Instance -> time until which it flashes after recombination merged it."""
    # refinement
    draft: HBL | None = None
    cloud: RefineCloud | None = None
    show_points: bool = True
    refine_revision: int = 0
    """Refinement edits so far (the server's ``RefineState.revision``)."""
    point_selection: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    """(M,) indices into the cloud selected for 'insert lobe'."""
    # sketching (both modes)
    strokes: list[np.ndarray] = field(default_factory=list)
    """Finished strokes waiting to be used, each (P, 3) world points."""
    live_stroke: dict[str, list] = field(default_factory=dict)
    """Hand side -> points of the stroke being drawn."""
    # feedback
    status: str = "ready"
    errors: list[str] = field(default_factory=list)
    scene_version: int = 0
    ui_version: int = 0
    exported: list[str] = field(default_factory=list)
    """Paths of files written by export."""

    def touch_scene(self) -> None:
        self.scene_version += 1
        self.ui_version += 1

    def clear_picks(self) -> None:
        """Forget what is selected and drawn: lobes or examples, points, finished strokes (Esc, a mode
        switch: points selected in one visit to refinement must not be inserted in the next)."""
        self.selection, self.strokes = [], []
        self.point_selection = np.zeros(0, np.int64)
        self.touch_scene()

    def say(self, text: str) -> None:
        self.status = text
        self.ui_version += 1
