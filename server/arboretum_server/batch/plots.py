"""Two small chart kinds drawn with Pillow (matplotlib is not a dependency): a scatter and a bar chart.

Both return a PIL image; axes with ticks at "nice" steps, a title, axis labels and (scatter) a legend.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

PALETTE = [(31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189), (140, 86, 75),
           (227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207)]
"""Series colours (RGB), cycled."""
MARGIN = (70, 40, 20, 50)
"""Plot area inset: left, top, right, bottom, pixels."""


def nice_ticks(lo: float, hi: float, n: int = 5) -> list[float]:
    """About ``n`` round tick values covering [lo, hi]."""
    if not hi > lo:
        hi = lo + 1.0
    raw = (hi - lo) / n
    mag = 10 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1, 2, 2.5, 5, 10) if m * mag >= raw)
    first = math.floor(lo / step) * step
    return [round(first + k * step, 10) for k in range(int(math.ceil((hi - first) / step)) + 1)]


class _Axes:
    def __init__(self, size: tuple[int, int], xr: list[float], yr: list[float], title: str,
                 xlabel: str, ylabel: str) -> None:
        from PIL import Image, ImageDraw, ImageFont

        self.img = Image.new("RGB", size, (255, 255, 255))
        self.d = ImageDraw.Draw(self.img)
        self.font = ImageFont.load_default()
        self.xr, self.yr = xr, yr
        w, h = size
        left, t, r, b = MARGIN
        self.box = (left, t, w - r, h - b)
        self.d.rectangle(self.box, outline=(0, 0, 0))
        self.d.text((w / 2, 8), title, fill=(0, 0, 0), font=self.font, anchor="mt")
        self.d.text((w / 2, h - 8), xlabel, fill=(0, 0, 0), font=self.font, anchor="mb")
        self.d.text((6, t - 16), ylabel, fill=(0, 0, 0), font=self.font)

    def px(self, x: float, y: float) -> tuple[float, float]:
        x0, y0, x1, y1 = self.box
        fx = (x - self.xr[0]) / (self.xr[-1] - self.xr[0])
        fy = (y - self.yr[0]) / (self.yr[-1] - self.yr[0])
        return x0 + fx * (x1 - x0), y1 - fy * (y1 - y0)

    def ticks(self, xt: Sequence[float] | None = None, xlabels: Sequence[str] | None = None) -> None:
        x0, y0, x1, y1 = self.box
        for v in self.yr:
            _, y = self.px(self.xr[0], v)
            self.d.line([(x0 - 4, y), (x0, y)], fill=(0, 0, 0))
            self.d.line([(x0 + 1, y), (x1 - 1, y)], fill=(235, 235, 235))
            self.d.text((x0 - 6, y), f"{v:g}", fill=(0, 0, 0), font=self.font, anchor="rm")
        for v, lab in zip(xt if xt is not None else self.xr, xlabels or [f"{v:g}" for v in self.xr]):
            x, _ = self.px(v, self.yr[0])
            self.d.line([(x, y1), (x, y1 + 4)], fill=(0, 0, 0))
            self.d.text((x, y1 + 6), lab, fill=(0, 0, 0), font=self.font, anchor="mt")


def scatter(series: dict[str, tuple[np.ndarray, np.ndarray]], title: str, xlabel: str, ylabel: str,
            size: tuple[int, int] = (720, 480)):
    """Scatter plot of named series {name: (x (N,), y (N,))}, one colour each, with a legend."""
    xs = np.concatenate([np.asarray(x, float) for x, _ in series.values()] or [np.zeros(1)])
    ys = np.concatenate([np.asarray(y, float) for _, y in series.values()] or [np.zeros(1)])
    ax = _Axes(size, nice_ticks(min(0.0, xs.min()), xs.max()), nice_ticks(min(0.0, ys.min()), ys.max()),
               title, xlabel, ylabel)
    ax.ticks()
    for k, (name, (x, y)) in enumerate(series.items()):
        c = PALETTE[k % len(PALETTE)]
        for xi, yi in zip(np.asarray(x, float), np.asarray(y, float)):
            px, py = ax.px(xi, yi)
            ax.d.ellipse([px - 3.5, py - 3.5, px + 3.5, py + 3.5], fill=c, outline=(0, 0, 0))
        lx, ly = ax.box[2] - 130, ax.box[1] + 8 + 16 * k
        ax.d.ellipse([lx, ly + 2, lx + 8, ly + 10], fill=c, outline=(0, 0, 0))
        ax.d.text((lx + 14, ly), f"{name} ({len(x)})", fill=(0, 0, 0), font=ax.font)
    return ax.img


def bars(values: Sequence[float], colours: Sequence[tuple[int, int, int]], title: str, xlabel: str,
         ylabel: str, size: tuple[int, int] = (720, 360)):
    """Vertical bars, one per value, in order, each with its own colour."""
    v = np.asarray(values, float)
    n = max(len(v), 1)
    ax = _Axes(size, [0.0, float(n)], nice_ticks(0.0, float(v.max()) if len(v) else 1.0), title, xlabel, ylabel)
    step = max(1, int(nice_ticks(0, n, 8)[1])) if n > 1 else 1
    ax.ticks([k + 0.5 for k in range(0, n, step)], [str(k + 1) for k in range(0, n, step)])
    for k, (val, c) in enumerate(zip(v, colours)):
        xa, ya = ax.px(k + 0.1, val)
        xb, yb = ax.px(k + 0.9, 0.0)
        ax.d.rectangle([xa, min(ya, yb - 1), max(xb, xa + 1), yb], fill=c)
    return ax.img
