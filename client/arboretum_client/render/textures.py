"""GPU textures of scene images (billboards, textured meshes): each uploaded once, cached across uploads.

Images are keyed by ``id(image)`` (the cache keeps the array alive so the id stays unique) and by how
they are sampled. Every texture is mipmapped and sampled trilinearly, mesh textures also
anisotropically where that is cheap (``default_anisotropy``). Cut-out textures (glTF alphaMode MASK: texels
with alpha below a cutoff are discarded) get their mipmaps built on the CPU by ``coverage_mipmaps``:
colour averaged over the opaque texels only, and alpha scaled per level so that the fraction of
texels passing the cutoff stays that of the full image (Castaño 2010, "Computing alpha mipmaps").
With plain averaged mipmaps a leaf card seen from afar either fades away or turns into a rectangle,
depending on its mean alpha.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import moderngl
import numpy as np

SOFTWARE_RASTERISERS = ("llvmpipe", "softpipe", "lavapipe", "swiftshader")
"""GL_RENDERER names of CPU rasterisers: anisotropic filtering is off there by default (16x made the
frames of a textured grown tree 5-7x slower on llvmpipe; see docs/rendering.md, Textures)."""


def default_anisotropy(ctx: moderngl.Context) -> float:
    """The context's maximum anisotropy (at most 16), or 1 (off) on a software rasteriser."""
    renderer = str(ctx.info.get("GL_RENDERER", "")).lower()
    if any(name in renderer for name in SOFTWARE_RASTERISERS):
        return 1.0
    return float(min(16.0, max(1.0, ctx.max_anisotropy)))


@dataclass(frozen=True)
class Sampling:
    """How an image is sampled: part of the cache key (one image may be used two ways)."""

    repeat: bool = False
    """Wrap texture coordinates outside 0..1 (tiling bark) instead of clamping (billboards)."""
    cutoff: float = 0.0
    """Alpha cutoff of a cut-out texture; > 0 selects coverage-preserving mipmaps."""
    anisotropic: bool = False
    """Filter anisotropically (``TextureCache.anisotropy``): sharper surfaces at grazing angles."""


def mip_sizes(width: int, height: int) -> list[tuple[int, int]]:
    """(w, h) of every mipmap level as OpenGL makes them: halved (rounded down) until 1 x 1."""
    sizes = [(width, height)]
    while sizes[-1] != (1, 1):
        w, h = sizes[-1]
        sizes.append((max(w // 2, 1), max(h // 2, 1)))
    return sizes


def _halve(a: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Box-filter (h, w, c) float ``a`` to ``size`` (w, h): 2 x 2 means (a dimension of 1 stays)."""
    w, h = size
    fy, fx = (2 if a.shape[0] > 1 else 1), (2 if a.shape[1] > 1 else 1)
    a = a[: h * fy, : w * fx]
    return a.reshape(h, fy, w, fx, a.shape[2]).mean(axis=(1, 3))


def coverage_mipmaps(image: np.ndarray, cutoff: float) -> list[np.ndarray]:
    """Mipmap levels (each (h, w, 4) uint8, level 0 = ``image``) of an RGBA cut-out texture.

    Args:
        image: (H, W, 4) uint8 RGBA, not premultiplied.
        cutoff: alpha cutoff in (0, 1]: a texel is drawn when its alpha >= cutoff.

    Colour is the alpha-weighted mean (transparent texels' colours do not bleed in); alpha is the
    plain mean scaled so that the fraction of texels at or above ``cutoff`` equals level 0's.
    """
    base = image.astype(np.float64) / 255.0
    target = float((base[..., 3] >= cutoff).mean())
    premul = np.concatenate([base[..., :3] * base[..., 3:], base[..., 3:]], axis=2)
    plain_rgb = base[..., :3]
    levels = [np.ascontiguousarray(image)]
    for size in mip_sizes(image.shape[1], image.shape[0])[1:]:
        premul, plain_rgb = _halve(premul, size), _halve(plain_rgb, size)
        alpha = premul[..., 3]
        rgb = np.where(alpha[..., None] > 1e-6, premul[..., :3] / np.maximum(alpha[..., None], 1e-6), plain_rgb)
        levels.append(_to_u8(np.concatenate([rgb, _keep_coverage(alpha, cutoff, target)[..., None]], axis=2)))
    return levels


def _keep_coverage(alpha: np.ndarray, cutoff: float, target: float) -> np.ndarray:
    """``alpha`` (h, w) scaled so that the fraction of it at or above ``cutoff`` is the smallest one
    its values allow that is >= ``target``: a level never shows less than the full image, so leaves
    seen from afar (a few pixels, sampled from the smallest levels) stay visible instead of vanishing."""
    if target <= 0.0:
        return np.minimum(alpha, cutoff * 0.5)
    ranked = np.sort(alpha.ravel())
    candidates = np.unique(ranked[ranked > 0.0])
    if not len(candidates):
        return alpha
    cover = 1.0 - np.searchsorted(ranked, candidates, side="left") / ranked.size  # falls as candidates rise
    threshold = candidates[max(int(np.count_nonzero(cover >= target - 1e-9)) - 1, 0)]
    at_cutoff = np.ceil(cutoff * 255.0) / 255.0  # a threshold texel stays >= cutoff once stored in 8 bits
    return np.clip(alpha * (at_cutoff / threshold), 0.0, 1.0)


def _to_u8(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(np.clip(np.rint(a * 255.0), 0, 255).astype(np.uint8))


def has_cutout(image: np.ndarray, cutoff: float) -> bool:
    """Whether any texel of (H, W, 4) ``image`` is cut out at ``cutoff``."""
    return cutoff > 0.0 and bool((image[..., 3] < cutoff * 255.0).any())


class TextureCache:
    """The textures of one GL context, one per (image, sampling), uploaded on first use."""

    def __init__(self, ctx: moderngl.Context, anisotropy: float | None = None) -> None:
        self.ctx = ctx
        self.anisotropy = default_anisotropy(ctx) if anisotropy is None else float(anisotropy)
        """Anisotropy of textures sampled ``anisotropic`` (1 = off), applied when they are uploaded."""
        self.entries: dict[tuple[int, Sampling], tuple[np.ndarray, moderngl.Texture]] = {}
        """(id(image), sampling) -> (that image, kept alive so the id stays unique; its texture)."""
        self.uploads = 0
        """Textures uploaded since this cache was made (tests check that the cache works)."""

    def get(self, image: np.ndarray, sampling: Sampling = Sampling()) -> moderngl.Texture:
        """The texture of (H, W, 4) uint8 ``image``, uploaded (with its mipmaps) if it is new."""
        key = (id(image), sampling)
        if key not in self.entries:
            self.entries[key] = (image, self._upload(image, sampling))
            self.uploads += 1
        return self.entries[key][1]

    def _upload(self, image: np.ndarray, sampling: Sampling) -> moderngl.Texture:
        h, w = image.shape[:2]
        tex = self.ctx.texture((w, h), 4, np.ascontiguousarray(image, np.uint8).tobytes())
        tex.build_mipmaps()  # allocates every level; cut-out textures then get their own levels
        if has_cutout(image, sampling.cutoff):
            for level, data in enumerate(coverage_mipmaps(image, sampling.cutoff)[1:], start=1):
                tex.write(data.tobytes(), level=level)
        tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        tex.repeat_x = tex.repeat_y = sampling.repeat
        if sampling.anisotropic and self.anisotropy > 1.0:
            tex.anisotropy = min(self.anisotropy, float(self.ctx.max_anisotropy))
        return tex

    def keep_only(self, used: Iterable[moderngl.Texture]) -> None:
        """Free every texture of this cache that is not in ``used``."""
        keep = {id(t) for t in used}
        for key in [k for k, (_, tex) in self.entries.items() if id(tex) not in keep]:
            self.entries.pop(key)[1].release()

    def release(self) -> None:
        self.keep_only(())


def bind(prog: moderngl.Program, name: str, texture: moderngl.Texture, unit: int = 0) -> None:
    """Bind ``texture`` to texture unit ``unit`` and point sampler uniform ``name`` of ``prog`` at it."""
    texture.use(unit)
    sampler = prog.get(name, None)
    if isinstance(sampler, moderngl.Uniform):
        sampler.value = unit
