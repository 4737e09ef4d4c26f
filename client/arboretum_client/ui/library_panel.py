"""Modeling panel: the library browser (keyword search, tag filter, example list) and modeling tools."""

from __future__ import annotations

from arboretum_client.tools.state import ClientState

from .widgets import DIM, LINE_H, TEXT, Canvas

TAGS = ("straight", "curved", "dense", "sparse")
WIDTH = 250
MAX_ROWS = 12


def draw(c: Canvas, s: ClientState) -> None:
    x0, y0 = 10, 10
    rows = min(len(s.library), MAX_ROWS)
    height = 36 + 2 * LINE_H + 14 + rows * (LINE_H + 2) + (LINE_H if len(s.library) > MAX_ROWS else 0) \
        + 8 + LINE_H + 2 + 6 * (LINE_H + 4) + 6
    y = c.panel((x0, y0, x0 + WIDTH, y0 + height), "Library")
    query = s.query + ("|" if s.search_focus else "")
    c.button((x0 + 8, y, x0 + WIDTH - 8, y + LINE_H), f"search: {query or '(press /)'}", "search:focus", s.search_focus)
    y += LINE_H + 6
    x = x0 + 8
    for tag in TAGS:
        w = 8 + 7 * len(tag)
        c.button((x, y, x + w, y + LINE_H), tag, f"tag:{tag}", s.tag_filter == tag)
        x += w + 4
    y += LINE_H + 8
    for row in s.library[:MAX_ROWS]:
        label = f"{row['id']}  {row.get('lobe_count', '?')} lobes  {' '.join(row.get('tags', ()))}"
        c.button((x0 + 8, y, x0 + WIDTH - 8, y + LINE_H), label[:38], f"choose:{row['id']}", s.chosen == row["id"])
        y += LINE_H + 2
    if len(s.library) > MAX_ROWS:
        c.text((x0 + 8, y), f"... {len(s.library) - MAX_ROWS} more", DIM)
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
