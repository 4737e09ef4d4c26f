"""Plain data of what to draw: no GL here, only numpy arrays in frozen records.

A ``Scene`` is a list of items plus an optional ground ``Grid``. Every item carries a ``pick_id``
(int > 0, 0 means "nothing") that the renderer writes into its ID buffer, so ``Renderer.pick`` can
say what is under a pixel; ``Scene.names`` maps ids to human names such as ``"branch:3"``.

Conventions: world frame, right-handed, Z up, metres. Colours are linear-ish RGB(A) in 0..1. Arrays
are float32 (GPU side) and copied read-only on construction.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from arboretum_library.errors import ValidationError

F32 = NDArray[np.float32]
I32 = NDArray[np.int32]


def _array(owner: object, name: str, dtype: type, shape: tuple) -> np.ndarray:
    """Copy ``owner.name`` to a read-only array of ``dtype`` and check its shape (None = any)."""
    arr = np.array(getattr(owner, name), dtype=dtype, copy=True)
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape)):
        raise ValidationError(f"{type(owner).__name__}.{name}: bad shape {arr.shape}, expected {shape}")
    if arr.dtype.kind == "f" and arr.size and not np.isfinite(arr).all():
        raise ValidationError(f"{type(owner).__name__}.{name}: holds NaN or infinite values")
    arr.flags.writeable = False
    object.__setattr__(owner, name, arr)
    return arr


def _rgba(owner: object, name: str) -> None:
    """Normalise ``owner.name`` (3 or 4 floats) to a (4,) float32 RGBA tuple-array."""
    c = np.array(getattr(owner, name), dtype=np.float32).reshape(-1)
    if c.shape not in ((3,), (4,)):
        raise ValidationError(f"{type(owner).__name__}.{name}: expected RGB or RGBA, got {c.shape}")
    object.__setattr__(owner, name, np.append(c, 1.0).astype(np.float32)[:4] if len(c) == 3 else c)


@dataclass(frozen=True, eq=False)
class PointSet:
    """Points drawn as round screen-space dots."""

    points: F32
    """(N, 3) float32, metres, world frame."""
    colors: F32
    """(N, 3) float32 RGB in 0..1, one per point."""
    size_px: float = 3.0
    """Dot diameter in output pixels."""
    pick_id: int = 0

    def __post_init__(self) -> None:
        pts = _array(self, "points", np.float32, (None, 3))
        _array(self, "colors", np.float32, (len(pts), 3))


@dataclass(frozen=True, eq=False)
class Polyline:
    """A polyline drawn as a tube (with per-vertex radii) or as a thick screen-space line."""

    points: F32
    """(N, 3) float32, metres, N >= 2."""
    radii: F32
    """(N,) float32, metres: tube radius per vertex (ignored for ``style='line'``)."""
    color: F32 = field(default_factory=lambda: np.array([0.1, 0.1, 0.1, 1.0], np.float32))
    """(4,) float32 RGBA (alpha must be 1: tubes are opaque)."""
    style: str = "tube"
    """'tube' (8-sided CPU tube mesh) or 'line' (screen-space line ``width_px`` wide)."""
    width_px: float = 2.0
    """Line width in output pixels for ``style='line'``."""
    pick_id: int = 0

    def __post_init__(self) -> None:
        pts = _array(self, "points", np.float32, (None, 3))
        if len(pts) < 2:
            raise ValidationError(f"Polyline.points: needs >= 2 vertices, got {len(pts)}")
        _array(self, "radii", np.float32, (len(pts),))
        _rgba(self, "color")
        if self.style not in ("tube", "line"):
            raise ValidationError(f"Polyline.style: {self.style!r} is not 'tube' or 'line'")


@dataclass(frozen=True, eq=False)
class Mesh:
    """A triangle mesh with one colour, optionally textured; translucent when ``color[3] < 1``."""

    vertices: F32
    """(V, 3) float32, metres."""
    faces: I32
    """(F, 3) int32 indices into ``vertices``, counter-clockwise seen from outside."""
    color: F32 = field(default_factory=lambda: np.array([0.7, 0.7, 0.7, 1.0], np.float32))
    """(4,) float32 RGBA; multiplies the texture's colour when there is one."""
    pick_id: int = 0
    normals: F32 | None = None
    """(V, 3) float32 unit vertex normals, or None for area-weighted ones from ``faces``."""
    uv: F32 | None = None
    """(V, 2) float32 texture coordinates, glTF convention: (0, 0) is the image's top-left texel,
    v grows downwards; the texture repeats outside 0..1. Needed when ``texture`` is given."""
    texture: NDArray[np.uint8] | None = None
    """(H, W, 4) uint8 RGBA, top row first, or None. An array that is already read-only is kept as
    it is (not copied), so meshes made from one array share one GPU texture."""
    alpha_cutoff: float = 0.5
    """Texels whose alpha is below this are cut out (not drawn, not pickable): glTF alphaMode MASK.
    0 draws every texel (glTF OPAQUE); only the texture's alpha is compared, never ``color[3]``."""
    double_sided: bool = True
    """Draw both faces of every triangle (glTF doubleSided); False culls the faces seen from behind."""

    def __post_init__(self) -> None:
        verts = _array(self, "vertices", np.float32, (None, 3))
        faces = _array(self, "faces", np.int32, (None, 3))
        _rgba(self, "color")
        if faces.size and (faces.min() < 0 or faces.max() >= len(verts)):
            raise ValidationError(f"Mesh.faces: indices must lie in 0..{len(verts) - 1}")
        if self.normals is not None:
            _array(self, "normals", np.float32, (len(verts), 3))
        if self.uv is not None:
            _array(self, "uv", np.float32, (len(verts), 2))
        if self.texture is not None:
            _texture(self, "texture")
            if self.uv is None:
                raise ValidationError("Mesh.uv: a textured mesh needs (V, 2) texture coordinates, got None")
        if not (np.isfinite(self.alpha_cutoff) and 0.0 <= self.alpha_cutoff <= 1.0):
            raise ValidationError(f"Mesh.alpha_cutoff: {self.alpha_cutoff} is not in 0..1")

    @property
    def translucent(self) -> bool:
        return bool(self.color[3] < 1.0)


def _texture(owner: object, name: str) -> None:
    """Check ``owner.name`` is an (H, W, 4) uint8 image; keep it when already read-only, else copy."""
    img = getattr(owner, name)
    kind = type(owner).__name__
    if not isinstance(img, np.ndarray) or img.dtype != np.uint8:
        raise ValidationError(f"{kind}.{name}: expected a uint8 numpy array, got "
                              f"{getattr(img, 'dtype', type(img).__name__)}")
    if img.ndim != 3 or img.shape[2] != 4 or img.shape[0] < 1 or img.shape[1] < 1:
        raise ValidationError(f"{kind}.{name}: bad shape {img.shape}, expected (H, W, 4) RGBA")
    if img.flags.writeable or not img.flags.c_contiguous:
        img = np.array(img, copy=True, order="C")
        img.flags.writeable = False
        object.__setattr__(owner, name, img)


@dataclass(frozen=True, eq=False)
class InstancedMesh:
    """One opaque mesh drawn N times (one draw call), e.g. leaves or modules."""

    mesh: Mesh
    """The shared mesh (its colour is used where ``colors`` is None; its texture, cutoff and
    sidedness apply to every instance)."""
    matrices: F32
    """(N, 4, 4) float32: T_world_instance for each instance (row-major, column vectors)."""
    colors: F32 | None = None
    """(N, 3) float32 RGB per instance (multiplying the texture), or None for ``mesh.color``."""

    def __post_init__(self) -> None:
        m = _array(self, "matrices", np.float32, (None, 4, 4))
        if self.colors is not None:
            _array(self, "colors", np.float32, (len(m), 3))

    @property
    def pick_id(self) -> int:
        return self.mesh.pick_id


@dataclass(frozen=True)
class Grid:
    """A square ground grid in the plane z = ``z``."""

    center: tuple[float, float] = (0.0, 0.0)
    """(x, y) metres of the grid centre."""
    half_size: float = 5.0
    """Half the side length, metres."""
    spacing: float = 1.0
    """Distance between lines, metres."""
    z: float = 0.0
    color: tuple[float, float, float, float] = (0.55, 0.57, 0.6, 1.0)


@dataclass(frozen=True, eq=False)
class Billboard:
    """A textured, alpha-blended rectangle in the world, e.g. a reference photo for image-guided
    modeling. Not pickable: it is left out of the ID pass, so items behind it stay pickable."""

    image: NDArray[np.uint8]
    """(H, W, 4) uint8 RGBA, top row first, not premultiplied (alpha 0 shows what is behind)."""
    center: F32
    """(3,) float32, metres, world frame: the rectangle's centre."""
    width: float
    """Metres along the image's rows (left to right)."""
    height: float
    """Metres along the image's columns (bottom to top)."""
    normal: F32 | None = field(default_factory=lambda: np.array([0.0, -1.0, 0.0], np.float32))
    """(3,) float32: the side the picture faces (default -Y, towards the front camera), or None to
    turn about the vertical axis through ``center`` so that it always faces the camera."""
    pick_id: int = 0

    def __post_init__(self) -> None:
        img = _array(self, "image", np.uint8, (None, None, 4))
        if img.shape[0] < 1 or img.shape[1] < 1:
            raise ValidationError(f"Billboard.image: empty image {img.shape}")
        _array(self, "center", np.float32, (3,))
        if not (np.isfinite(self.width) and np.isfinite(self.height) and self.width > 0 and self.height > 0):
            raise ValidationError(f"Billboard: width and height must be > 0, got {self.width} x {self.height}")
        if self.normal is not None and not np.linalg.norm(_array(self, "normal", np.float32, (3,))) > 0:
            raise ValidationError("Billboard.normal: must not be the zero vector")

    def axes(self, eye: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(right, up): (3,) float64 half-extent vectors in the world frame (``eye`` (3,) is used
        only when ``normal`` is None)."""
        if self.normal is None:
            n = np.asarray(eye if eye is not None else (0.0, -1.0, 0.0), np.float64) - self.center
            n[2] = 0.0
        else:
            n = np.asarray(self.normal, np.float64).copy()
        n = n / np.linalg.norm(n) if np.linalg.norm(n) > 1e-9 else np.array([0.0, -1.0, 0.0])
        up = np.array([0.0, 0.0, 1.0]) if abs(n[2]) < 0.999 else np.array([0.0, 1.0, 0.0])
        right = np.cross(up, n)
        right /= np.linalg.norm(right)
        return right * (self.width / 2), np.cross(n, right) * (self.height / 2)

    def corners(self, eye: np.ndarray | None = None) -> np.ndarray:
        """(4, 3) float64 world corners: bottom-left, bottom-right, top-left, top-right."""
        r, u = self.axes(eye)
        c = self.center.astype(np.float64)
        return np.stack([c - r - u, c + r - u, c - r + u, c + r + u])


Item = PointSet | Polyline | Mesh | InstancedMesh | Billboard


@dataclass(frozen=True)
class Scene:
    """Everything to draw in one frame."""

    items: tuple[Any, ...] = ()
    """PointSet, Polyline, Mesh, InstancedMesh and Billboard records."""
    grid: Grid | None = None
    names: dict[int, str] = field(default_factory=dict)
    """pick_id -> a name such as 'branch:0' or 'lobe:2'."""

    def bounds(self) -> np.ndarray:
        """(2, 3) float64: min and max corner of every item (the grid excluded)."""
        pts = [_item_points(it) for it in self.items]
        pts = [p for p in pts if len(p)]
        if not pts:
            return np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])
        allp = np.concatenate(pts).astype(np.float64)
        return np.stack([allp.min(axis=0), allp.max(axis=0)])


def _item_points(item: Any) -> np.ndarray:
    if isinstance(item, PointSet | Polyline):
        return item.points
    if isinstance(item, Mesh):
        return item.vertices
    if isinstance(item, Billboard):
        return item.corners()
    if isinstance(item, InstancedMesh):  # the mesh's box corners under every instance transform
        v = item.mesh.vertices
        lo, hi = v.min(axis=0), v.max(axis=0)
        corners = np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        return (item.matrices.astype(np.float64) @ corners.T).transpose(0, 2, 1)[..., :3].reshape(-1, 3)
    raise TypeError(f"not a scene item: {type(item).__name__}")


def grid_for_bounds(bounds: np.ndarray) -> Grid:
    """A ground grid under ``bounds`` (2, 3), twice as wide as the object, with a round spacing."""
    lo, hi = np.asarray(bounds, dtype=np.float64)
    half = float(max(hi[0] - lo[0], hi[1] - lo[1], (hi[2] - lo[2]) * 0.5, 1e-3))
    step = 10.0 ** np.floor(np.log10(half / 4))
    for mult in (1.0, 2.0, 5.0):
        if half / (step * mult) <= 10:
            step *= mult
            break
    centre = (lo[:2] + hi[:2]) / 2
    return Grid(center=(float(centre[0]), float(centre[1])), half_size=half * 1.5, spacing=float(step), z=float(lo[2]))
