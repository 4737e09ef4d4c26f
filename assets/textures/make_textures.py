"""Make the bundled bark and leaf textures procedurally (numpy + pillow); run from anywhere:

    .venv/bin/python assets/textures/make_textures.py

bark.png: 256x256 RGB, tiles in both directions (vertical furrows with periodic noise).
leaf.png: 128x256 RGBA, a leaf with its stem at the bottom and tip at the top, transparent outside.
Both are deterministic (fixed seed), so re-running gives the same bytes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

HERE = Path(__file__).resolve().parent


def periodic_noise(rng: np.random.Generator, shape: tuple[int, int], octaves: int = 5) -> np.ndarray:
    """Tileable fractal noise in [0, 1] built from random Fourier coefficients (1/f spectrum)."""
    h, w = shape
    fy = np.fft.fftfreq(h)[:, None] * h
    fx = np.fft.fftfreq(w)[None, :] * w
    f = np.sqrt(fx**2 + fy**2)
    amp = np.where(f > 0, 1.0 / np.maximum(f, 1.0) ** 1.6, 0.0) * (f < 2 ** (octaves + 1))
    spec = amp * np.exp(2j * np.pi * rng.random((h, w)))
    n = np.real(np.fft.ifft2(spec))
    return (n - n.min()) / (n.max() - n.min())


def bark(rng: np.random.Generator, size: int = 256) -> np.ndarray:
    """(size, size, 3) uint8 tileable bark: stretched furrows plus fine grain."""
    coarse = periodic_noise(rng, (size // 8, size))
    coarse = np.repeat(coarse, 8, axis=0)
    coarse = np.roll(coarse, 4, axis=0) * 0.5 + coarse * 0.5
    fine = periodic_noise(rng, (size, size), octaves=7)
    x = np.arange(size) / size
    ridges = 0.5 + 0.5 * np.sin(2 * np.pi * (6 * x[None, :] + 0.6 * coarse))
    v = np.clip(0.55 * ridges + 0.3 * coarse + 0.25 * fine, 0, 1)[..., None]
    dark, light = np.array([46, 32, 22]), np.array([132, 108, 84])
    return (dark + (light - dark) * v).astype(np.uint8)


def leaf(rng: np.random.Generator, w: int = 128, h: int = 256) -> np.ndarray:
    """(h, w, 4) uint8 leaf: stem at the bottom centre, tip at the top, alpha 0 outside."""
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    t = 1.0 - y / (h - 1)  # 0 at the stem (bottom), 1 at the tip (top)
    xc = (x - (w - 1) / 2) / ((w - 1) / 2)
    half = 0.95 * np.sin(np.pi * np.clip((t - 0.06) / 0.94, 0, 1)) ** 0.8
    inside = np.abs(xc) <= half
    stem = (t < 0.08) & (np.abs(xc) < 0.05)
    vein = np.abs(xc) < 0.03 + 0.02 * (1 - t)
    side_veins = np.abs(np.sin(np.pi * 9 * (t - 0.6 * np.abs(xc)))) < 0.08
    noise = periodic_noise(rng, (h, w), octaves=6)
    g = 0.75 + 0.25 * noise - 0.15 * np.abs(xc)
    rgb = np.stack([60 * g, 135 * g, 45 * g], -1)
    rgb[vein | (side_veins & inside)] *= 1.25
    rgb[stem] = [90, 110, 50]
    alpha = np.where(inside | stem, 255, 0)
    return np.dstack([np.clip(rgb, 0, 255), alpha]).astype(np.uint8)


def main() -> None:
    rng = np.random.default_rng(20240601)
    Image.fromarray(bark(rng), "RGB").save(HERE / "bark.png", optimize=True)
    Image.fromarray(leaf(rng), "RGBA").save(HERE / "leaf.png", optimize=True)
    for name in ("bark.png", "leaf.png"):
        print(name, (HERE / name).stat().st_size, "bytes")


if __name__ == "__main__":
    main()
