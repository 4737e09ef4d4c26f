"""Refinement panel: the draft's lobes, the selection, and the refinement operations (VRTree 3.3)."""

from __future__ import annotations

from arboretum_client.tools.state import ClientState
from arboretum_library.model import Level

from .widgets import DIM, LINE_H, PANEL_W, PANEL_X, TEXT, Canvas


def draw(c: Canvas, s: ClientState, width: int = PANEL_W, bottom: int | None = None) -> None:
    """The panel ``width`` pixels wide from (``PANEL_X``, ``PANEL_X``) (``bottom`` is unused: its content is fixed)."""
    x0 = y0 = PANEL_X
    y = c.panel((x0, y0, x0 + width, y0 + 330), "Refinement")
    hbl = s.draft
    if hbl is None:
        c.text((x0 + 8, y), "no draft: open a scan", DIM)
        y += LINE_H
    else:
        c.text((x0 + 8, y), f"{len(hbl.branches)} branches, {len(hbl.lobes)} lobes", TEXT)
        y += LINE_H
        c.text((x0 + 8, y), f"selected: {', '.join(s.selection) or '-'}"[:max((width - 10) // 6, 4)], DIM)
        y += LINE_H
        c.text((x0 + 8, y), f"points selected: {len(s.point_selection)}", DIM)
        y += LINE_H
        c.text((x0 + 8, y), f"strokes: {len(s.strokes)}", DIM)
        y += LINE_H + 6
    rows = [
        [("remove lobe", "menu", False), ("insert / split / merge", "touchpad", False)],
        [("hide points" if s.show_points else "show points", "toggle:show_points", not s.show_points)],
        [("show all" if s.show_all else f"show one ({_shown(s)})", "toggle:show_all", not s.show_all),
         ("next", "focus:+", False)],
        [("undo", "undo", False), ("redo", "redo", False)],
        [("commit to library", "commit", False)],
        [("modeling", "mode", False)],
    ]
    y = c.button_rows(x0, y, rows)


def _shown(s) -> str:
    """'K of M': the main branch (example) shown, as ``view._focus_branches`` picks it (focus mod M)."""
    mains = sum(b.level == Level.MAIN for b in s.draft.branches) if s.draft is not None else 0
    return f"{s.focus % mains + 1} of {mains}" if mains else str(s.focus)
