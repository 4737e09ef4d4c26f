"""Hand-made 2D widgets drawn with Pillow into an RGBA image (no GL here).

Why not Dear ImGui: its Python bindings bring their own GL backend and event handling (pyimgui's
moderngl renderer is unmaintained; imgui-bundle is a large native wheel), and in VR the panels would have
to be textures anyway. Our panels change only when the state changes, so the frame loop redraws the
image on change (a few ms with Pillow) and the renderer draws it each frame as one textured triangle.

A ``Canvas`` records the rectangle of every clickable widget with an action name; ``hit`` maps a pixel
to that action.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

PANEL_BG = (24, 28, 34, 200)
TEXT = (235, 238, 242, 255)
DIM = (150, 158, 170, 255)
ACCENT = (90, 160, 255, 255)
BUTTON = (52, 60, 72, 230)
BUTTON_ON = (70, 120, 200, 240)
LINE_H = 18
CHAR_W = 7
"""Pixels per character of the 13 px default font (an upper bound, for sizing buttons and cutting text)."""
PANEL_W = 250
"""Width of the side panel in pixels when the output is wide enough."""
PANEL_X = 10
"""The side panel's left (and top) margin."""


@lru_cache(maxsize=4)
def font(size: int = 13):
    from PIL import ImageFont

    return ImageFont.load_default(size=size)


@dataclass
class Canvas:
    """An RGBA image the panels draw into, and the clickable regions they leave."""

    size: tuple[int, int]
    regions: list[tuple[tuple[int, int, int, int], str]] = field(default_factory=list)
    """((x0, y0, x1, y1), action) for each clickable widget, in drawing order."""

    def __post_init__(self) -> None:
        from PIL import Image, ImageDraw

        self.image = Image.new("RGBA", self.size, (0, 0, 0, 0))
        self.draw = ImageDraw.Draw(self.image)

    def panel(self, box: tuple[int, int, int, int], title: str) -> int:
        """A translucent panel with a title; returns the y of the first content line."""
        self.draw.rounded_rectangle(box, radius=6, fill=PANEL_BG)
        self.text((box[0] + 8, box[1] + 6), title, ACCENT, size=14)
        return box[1] + 6 + LINE_H + 4

    def text(self, xy, text: str, color=TEXT, size: int = 13) -> None:
        self.draw.text(xy, text, fill=color, font=font(size))

    def button(self, box: tuple[int, int, int, int], label: str, action: str, on: bool = False) -> None:
        self.draw.rounded_rectangle(box, radius=4, fill=BUTTON_ON if on else BUTTON)
        self.text((box[0] + 6, box[1] + 2), label, TEXT)
        self.regions.append((box, action))

    def button_rows(self, x0: int, y: int, rows: list[list[tuple[str, str, bool]]]) -> int:
        """Rows of (label, action, on) buttons sized to their labels, from (x0 + 8, y); the y below them."""
        for row in rows:
            x = x0 + 8
            for label, action, on in row:
                w = 10 + CHAR_W * len(label)
                self.button((x, y, x + w, y + LINE_H), label, action, on)
                x += w + 4
            y += LINE_H + 4
        return y

    def bar(self, box: tuple[int, int, int, int], fraction: float | None) -> None:
        """A progress bar; ``None`` draws an indeterminate (striped) bar. An empty box draws nothing."""
        x0, y0, x1, y1 = box
        if x1 <= x0 or y1 <= y0:
            return
        self.draw.rectangle(box, fill=BUTTON)
        if fraction is None:
            for x in range(x0, x1, 12):
                self.draw.rectangle((x, y0, min(x + 5, x1), y1), fill=ACCENT)
        else:
            self.draw.rectangle((x0, y0, x0 + int((x1 - x0) * max(0.0, min(1.0, fraction))), y1), fill=ACCENT)

    def hit(self, x: float, y: float) -> str | None:
        for (x0, y0, x1, y1), action in reversed(self.regions):
            if x0 <= x <= x1 and y0 <= y <= y1:
                return action
        return None

    def covers(self, x: float, y: float) -> bool:
        """True where a panel was drawn (clicks there never reach the 3D scene)."""
        xi, yi = int(x), int(y)
        if not (0 <= xi < self.size[0] and 0 <= yi < self.size[1]):
            return False
        pixel = self.image.getpixel((xi, yi))
        return isinstance(pixel, tuple) and pixel[3] > 0

    def rgba(self) -> np.ndarray:
        """(H, W, 4) uint8, top row first."""
        return np.asarray(self.image, np.uint8)
