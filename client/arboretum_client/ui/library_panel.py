"""Modeling panel: the library browser (keyword search, tag filter, example list) and modeling tools."""

from __future__ import annotations

from arboretum_client.tools.state import ClientState
from arboretum_client.ui_actions import TAGS

from .widgets import CHAR_W, DIM, LINE_H, PANEL_W, PANEL_X, TEXT, Canvas

MAX_ROWS = 12
FIXED_H = 36 + 2 * LINE_H + 14 + 8 + LINE_H + 2 + 6 * (LINE_H + 4) + 6
"""Height of everything but the example rows (title, search, tags, tool buttons)."""


def fitting_rows(n: int, space: int) -> tuple[int, bool]:
    """(rows shown, whether a '... more' line is needed) for ``n`` examples in ``space`` pixels of panel."""
    rows = min(n, MAX_ROWS, max((space - FIXED_H) // (LINE_H + 2), 0))
    if rows < n:  # the '... more' line takes a row's place when space is short
        rows = min(rows, max((space - FIXED_H - LINE_H) // (LINE_H + 2), 0))
    return rows, rows < n


def draw(c: Canvas, s: ClientState, width: int = PANEL_W, bottom: int | None = None) -> None:
    """The panel ``width`` pixels wide from (``PANEL_X``, ``PANEL_X``), its example list cut to end above ``bottom``."""
    x0 = y0 = PANEL_X
    rows, more = fitting_rows(len(s.library), (c.size[1] if bottom is None else bottom) - y0)
    height = FIXED_H + rows * (LINE_H + 2) + (LINE_H if more else 0)
    chars = max((width - 28) // CHAR_W, 4)
    y = c.panel((x0, y0, x0 + width, y0 + height), "Library")
    query = s.query + ("|" if s.search_focus else "")
    c.button((x0 + 8, y, x0 + width - 8, y + LINE_H), f"search: {query or '(press /)'}"[:chars], "search:focus",
             s.search_focus)
    y += LINE_H + 6
    x = x0 + 8
    for tag in TAGS:
        w = 8 + CHAR_W * len(tag)
        c.button((x, y, x + w, y + LINE_H), tag, f"tag:{tag}", s.tag_filter == tag)
        x += w + 4
    y += LINE_H + 8
    for row in s.library[:rows]:
        label = f"{row['id']}  {row.get('lobe_count', '?')} lobes  {' '.join(row.get('tags', ()))}"
        c.button((x0 + 8, y, x0 + width - 8, y + LINE_H), label[:min(38, chars)], f"choose:{row['id']}",
                 s.chosen == row["id"])
        y += LINE_H + 2
    if more:
        c.text((x0 + 8, y), f"... {len(s.library) - rows} more", DIM)
        y += LINE_H
    y += 8
    c.text((x0 + 8, y), "Modeling", TEXT, size=14)
    y += LINE_H + 2
    _tool_buttons(c, s, x0, y)


def _tool_buttons(c: Canvas, s: ClientState, x0: int, y: int) -> None:
    rows = [
        [("undo", "undo", False), ("redo", "redo", False), ("delete", "menu", False)],
        [("sketch -> example", "touchpad", bool(s.strokes))],
        [("show all" if s.show_all else "show one", "toggle:show_all", not s.show_all)],
        [("density -", "density:-", False), (f"{s.density:.2f}", "noop", False), ("+", "density:+", False)],
        [("grow", "grow", s.grown is not None), ("export", "export", False)],
        [("save", "save", False), ("load", "load", False), ("refine", "mode", False)],
    ]
    y = c.button_rows(x0, y, rows)
