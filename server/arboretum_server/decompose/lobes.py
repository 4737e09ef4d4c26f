"""Lobes (VRTree section 3.4): k-means of foliage points into N_l clusters, an alpha shape per cluster.

The alpha shape is built from the Delaunay tetrahedralisation of the cluster: tetrahedra whose
circumradius is below the probe radius are kept, and the hull is the set of triangles that belong to
exactly one kept tetrahedron, each oriented away from its tetrahedron. Such a boundary is closed, unlike
open3d's alpha meshes of surface-like clusters (a measurement kept outside the repository), but can
pinch or fall apart, so the probe radius 1/alpha (0.8 m frame) is tried at each of ``RADIUS_STEPS``
times itself, and the first shape that touches at least ``MIN_COVER`` of the cluster's points and is a
closed, one-piece 2-manifold is taken. Flat tetrahedra (points on a grid) are never under the probe
radius but fill the holes of no volume they would leave inside the shape (``_walled_in``).
When none is, or the cluster is degenerate (fewer than 5 points, flat), we fall back to the convex hull
(boxed by ``PAD`` for flat or tiny clusters), oriented outward. A *carved* alpha shape (``carved_hull``)
also keeps out of given blocker points (main-branch wood a lobe wraps round, ``carve.unwrap``).
"""

from __future__ import annotations

import copy
import os
import signal
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from scipy.spatial import ConvexHull, Delaunay, QhullError, cKDTree

from arboretum_library import signals
from arboretum_server.jitcache import njit

from .graph import query_threads
from .tetloops import boundary as _boundary
from .tetloops import circumspheres as _circumspheres
from .tetloops import compact as _compacted
from .tetloops import covered as _covered
from .tetloops import drop_edges as _drop_edges
from .tetloops import flat as _flat
from .tetloops import held as _held
from .tetloops import is_closed_manifold as is_closed_manifold
from .tetloops import orient as _orient
from .tetloops import pinched_edges as _pinched

MIN_COVER = 0.95
"""Smallest fraction of a cluster's points the alpha shape must touch; otherwise the convex hull."""
PAD = 0.004
"""Half-size (0.8 m frame) of the box added around degenerate clusters before taking the hull."""
PINCH_ROUNDS = 8
"""Rounds of dropping the tetrahedra at pinched edges of a carved alpha shape (``alpha_shape``)."""
DENSE = 2000
"""Clusters with more points than this are tetrahedralised on a thinned subset (``thin``): only
``decompose --points 0`` and other dense inputs have such lobes (12,000 points give 14-553 a lobe on the
bundled scans, medians 145-201)."""
THIN = 16
"""The thinning cell of a dense cluster is the probe radius / ``THIN`` (1/13 / 16 = 4.8 mm at the 0.8 m
scale)."""
FLAT = 1e-10
"""A tetrahedron whose volume (times 6) is below this fraction of its longest edge cubed is flat
(``_walled_in``): on the 1 cm grid of scan 10 at full resolution 1,327 of its 2,200 tetrahedra wider
than 3 probe radii lie below 1e-12 and the rest above 1e-6 (session 18)."""


def kmeans(points: np.ndarray, k: int, rng: np.random.Generator, init: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Cluster ``points`` (N, 3) into ``k`` groups: (labels (N,) int32, centres (k, 3)), by ``clusters.kmeans``
    (k-means++ and Lloyd's rounds, compiled, one thread: the same centres on any machine) seeded by one draw
    from ``rng``. Until session 30 scikit-learn's ``KMeans`` (on one OpenMP thread, session 24), whose import
    cost every ``arboretum decompose`` 0.9-1.3 s."""
    from .clusters import kmeans as _kmeans

    seed = int(rng.integers(2**31 - 1))  # one draw, as before: the caller's generator moves on as it did
    return _kmeans(points, k, np.random.default_rng(seed), init)


class Tetrahedra:
    """The Delaunay tetrahedralisation of a cluster's points with the neighbours and circumsphere of every
    tetrahedron: built once, cut at as many probe radii as ``plain_hull`` and ``carved_hull`` try, and
    carved (``without``) by as many sets of blockers."""

    def __init__(self, points: np.ndarray, cell: float = 0.0):
        self.source = np.asarray(points, dtype=np.float64)
        self.points = thin(self.source, cell) if len(self.source) > DENSE else self.source
        self.n_own = len(self.points)
        self.carve = False
        self.tets = np.zeros((0, 4), np.int32)
        self.neighbours = np.zeros((0, 4), np.int32)
        self.radii, self.centres = np.zeros(0), np.zeros((0, 3))
        self.flat = np.zeros(0, bool)
        if self.n_own < 5:
            return
        try:
            dt = Delaunay(self.points)
        except QhullError:
            return
        self.tets, self.neighbours = dt.simplices, dt.neighbors
        corners = self.points[self.tets]
        self.centres, self.radii = _circumspheres(corners)
        self.flat = _flat(corners, FLAT)
        self.radii[self.flat] = np.inf  # a rounding-sized volume gives any radius at all

    def without(self, blockers: np.ndarray | None, reach: float = np.inf) -> Tetrahedra:
        """The tetrahedra that stay when ``blockers`` (B, 3) join the tetrahedralisation and every
        tetrahedron touching one is dropped: those whose circumsphere holds no blocker (inserting a point
        into a Delaunay tetrahedralisation removes exactly the tetrahedra whose circumsphere holds it, and
        every tetrahedron it adds touches it). The shapes of the result also drop pinched edges.
        ``reach``: the largest probe radius its shapes are asked for; tetrahedra with larger circumspheres
        (never in those shapes) are not tested (session 15: 2-3 times fewer queries, the same shapes)."""
        if blockers is None or len(blockers) == 0 or not len(self.tets):
            return self
        out = copy.copy(self)
        out.carve = True
        blockers = np.ascontiguousarray(blockers, dtype=np.float64)
        live = np.flatnonzero(self.radii < reach)
        held = _held(self.centres[live], self.radii[live], blockers)
        unsure = live[held == 2]
        out.radii = self.radii.copy()
        out.radii[live[held == 1]] = np.inf
        if len(unsure):  # seldom: no KD-tree of the blockers built for nothing (session 29)
            near = cKDTree(blockers).query(self.centres[unsure], distance_upper_bound=reach)[0]
            out.radii[unsure[near < self.radii[unsure]]] = np.inf
        return out


    def shape(self, radius: float) -> tuple[np.ndarray, np.ndarray] | None:
        """The alpha shape at probe radius ``radius``, as ``alpha_shape`` returns it (flat tetrahedra
        walled in by kept ones filled, ``_walled_in``)."""
        keep = _walled_in(self.neighbours, self.flat, self.radii < radius)
        if not keep.any():
            return None
        faces, opp = _boundary(self.tets, self.neighbours, keep)
        for _ in range(PINCH_ROUNDS if self.carve else 0):
            pinched = _pinched_edges(faces)
            if not len(pinched):
                break
            _drop_edges(self.tets, keep, pinched)
            if not keep.any():
                break
            faces, opp = _boundary(self.tets, self.neighbours, keep)
        if not keep.any() or _covered(self.tets, keep, len(self.points)) < MIN_COVER * self.n_own:
            return None
        return _compact(self.points, _orient(self.points, faces, opp))


def _walled_in(neighbours: np.ndarray, flat: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """``keep`` (T,) bool with the ``flat`` (T,) tetrahedra added whose every neighbour is kept or another
    such flat one: holes of no volume inside the shape, filled.

    Why: points on a grid (scan 10 is stored at 1 cm) are often four on a circle, and qhull splits such
    a cell into tetrahedra some of which are flat, with no true circumsphere. Left out, each leaves a
    hole whose walls are extra pieces of the boundary: 39 of the 40 lobes of scan 10 at ``--points 0``
    fell back to the convex hull (session 18). A flat one on the boundary stays out: the faces it would
    add have no inside to orient them by.
    """
    fill = flat & ~keep
    todo = np.flatnonzero(fill)
    while len(todo):
        nb = neighbours[todo]
        walled = ((nb >= 0) & (keep | fill)[nb]).all(axis=1)
        if walled.all():
            break
        fill[todo[~walled]] = False
        todo = todo[walled]
    return keep | fill


def thin(points: np.ndarray, cell: float) -> np.ndarray:
    """``points`` (N, 3) with one point kept per cube of side ``cell`` (all of them for ``cell`` <= 0):
    the one farthest from their mean, so the outer points that shape the hull stay. Points dropped lie
    within a cell diagonal of a kept one, and seldom outside the hull: a cluster's outermost points
    are each the farthest of their cube."""
    from arboretum_library.pointio_spatial import voxel_keys

    if cell <= 0 or not len(points):
        return points
    flat = voxel_keys(points, cell)
    far = np.linalg.norm(points - points.mean(axis=0), axis=1)
    order = np.lexsort((-far, flat))
    first = np.ones(len(order), bool)
    first[1:] = flat[order][1:] != flat[order][:-1]
    return points[np.sort(order[first])]


def alpha_shape(points: np.ndarray, radius: float,
                blockers: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray] | None:
    """Closed alpha shape (vertices (V, 3), outward faces (F, 3) int32) of ``points``, or None.

    With ``blockers`` (B, 3), the tetrahedra that would touch one if they joined the Delaunay
    tetrahedralisation are dropped (``Tetrahedra.without``): the shape then reaches from its points up
    to, but not across, the blockers. The tunnel
    this cuts often pinches the boundary (two tetrahedra meeting only along an edge); the tetrahedra at
    pinched edges are dropped too, for up to ``PINCH_ROUNDS`` rounds.
    """
    return Tetrahedra(points).without(blockers).shape(radius)


def _edge_keys(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Undirected edge keys (E,) int64 of the vertex pairs ``a``, ``b`` (E,) (indices < 2**31)."""
    lo, hi = np.minimum(a, b).astype(np.int64), np.maximum(a, b).astype(np.int64)
    return lo * (1 << 32) + hi


def _pinched_edges(faces: np.ndarray) -> np.ndarray:
    """Keys of the edges that border more than two of ``faces`` (F, 3): ``_pinched_edges_reference`` compiled
    (``tetloops.pinched_edges``)."""
    return _pinched(faces)


def _pinched_edges_reference(faces: np.ndarray) -> np.ndarray:
    """``_pinched_edges`` in numpy (the reference the tests hold it to)."""
    keys = np.concatenate([_edge_keys(faces[:, i], faces[:, (i + 1) % 3]) for i in range(3)])
    u, cnt = np.unique(keys, return_counts=True)
    return u[cnt > 2]


def _compact(points: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``_compact_reference`` in one compiled call (``tetloops.compact``), the same arrays."""
    return _compacted(points, faces) or _compact_reference(points, faces)


def _compact_reference(points: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the points ``faces`` (F, 3) use, in index order; the faces renumbered into them, int32): what
    ``np.unique(faces, return_inverse=True)`` gives, by a mask and its running count instead of a sort."""
    mark = np.zeros(len(points), bool)
    mark[faces.ravel()] = True
    rank = np.cumsum(mark) - 1
    return points[mark], rank[faces].astype(np.int32)


def convex_hull(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Convex hull (vertices, outward faces int32) of ``points`` (N >= 1, 3); boxed if degenerate."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    try:
        if len(pts) < 4:
            raise QhullError("too few points")
        hull = ConvexHull(pts)
        if hull.volume < 1e-12:
            raise QhullError("flat")
    except QhullError:
        corners = np.array(np.meshgrid(*[[-PAD, PAD]] * 3)).reshape(3, -1).T
        pts = (pts[:, None, :] + corners[None]).reshape(-1, 3)
        hull = ConvexHull(pts)
    faces = hull.simplices.copy()
    f = pts[faces]
    n = np.cross(f[:, 1] - f[:, 0], f[:, 2] - f[:, 0])
    inner = pts[hull.vertices].mean(axis=0)
    flip = ((f[:, 0] - inner) * n).sum(axis=1) < 0
    faces[flip] = faces[flip][:, [0, 2, 1]]
    return _compact(pts, faces)


RADIUS_STEPS = (1.0, 1.5, 2.0, 3.0)
"""Multiples of the probe radius tried, in order, until the alpha shape is a closed 2-manifold."""


def lobe_hull(points: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray, bool]:
    """(vertices, faces, used_alpha): a closed, one-piece alpha shape of ``points``, else its convex hull.

    The boundary of a union of tetrahedra is closed but can pinch (two tetrahedra meeting along an
    edge leave it with four faces) or fall apart into islands; growing the probe radius through
    ``RADIUS_STEPS`` usually fills such gaps before the convex hull is needed.
    """
    return plain_hull(points, radius)[:3]


def plain_hull(points: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray, bool, tuple[float, ...], Tetrahedra]:
    """``lobe_hull``, the ``RADIUS_STEPS`` up to the one it used (all of them for a convex hull): what
    ``plain_steps`` would compute again, and the tetrahedralisation (for ``carved_hull``)."""
    tet = Tetrahedra(points, radius / THIN)
    for i, step in enumerate(RADIUS_STEPS):
        shape = tet.shape(radius * step)
        if shape is not None and is_closed_manifold(shape[1]):
            return shape[0], shape[1], True, RADIUS_STEPS[: i + 1], tet
    v, f = convex_hull(points)
    return v, f, False, RADIUS_STEPS, tet


HULL_POOL_MEAN = 50
"""``plain_hulls`` builds its hulls in threads only when they hold this many points each on average: smaller
hulls spend most of their time in Python, holding the GIL, and the threads only take it from each other
(session 27, wall on 2 cores: 20 hulls of 10-40 points 1.1-2.8 times one thread's, e.g. a split's 20
pieces; 3-20 hulls of 50-60 points 0.82-1.02; 100 points and more 0.51-0.87)."""


def hull_threads() -> int:
    """Threads for ``plain_hulls``: ``OMP_NUM_THREADS`` when it is a whole number >= 1 (``graph.query_threads``;
    a batch worker sets it to 1: its parallelism comes from processes), else the cores this process may run on."""
    threads = query_threads()
    if threads >= 1:
        return threads
    cores = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else range(os.cpu_count() or 1)
    return max(len(cores), 1)


def plain_hulls(point_sets: list[np.ndarray], radius: float) -> list[tuple]:
    """``[plain_hull(p, radius) for p in point_sets]``, the same results in the same order, built on
    ``hull_threads()`` threads (this one and the pool's) when the sets hold ``HULL_POOL_MEAN`` points each on
    average: qhull and the compiled loops of ``Tetrahedra`` and ``shape`` release the GIL, and each hull is built
    from its own points alone (what is remembered of a hull, ``carve.remember_plain``, the caller keeps).
    The threads take the hulls largest first, one at a time, until none is left.

    A Ctrl-C raises ``KeyboardInterrupt`` here at once (one while the pool's threads start, held back for
    those microseconds, just after it); the hulls not started are dropped and the pool's hull under way
    (a few ms) ends before it leaves, so no thread outlives the call."""
    threads = min(hull_threads(), len(point_sets))
    if threads <= 1 or sum(len(p) for p in point_sets) < HULL_POOL_MEAN * len(point_sets):
        return [plain_hull(p, radius) for p in point_sets]
    out: list = [None] * len(point_sets)
    todo = iter(sorted(range(len(point_sets)), key=lambda i: -len(point_sets[i])))

    def build() -> None:
        for i in todo:  # one list iterator shared by the threads: each index comes out once
            out[i] = plain_hull(point_sets[i], radius)

    pool = ThreadPoolExecutor(threads - 1, thread_name_prefix="plain_hulls")
    try:
        with signals.held(signal.SIGINT) as got:  # a thread interrupted while it starts would not be waited for
            helpers = [pool.submit(build) for _ in range(threads - 1)]
        if got:
            signal.raise_signal(signal.SIGINT)
        build()
        for h in helpers:
            h.result()
    except BaseException:
        for _ in todo:  # the hulls not started are dropped
            pass
        raise
    finally:
        pool.shutdown(wait=True)
    return out


def carved_hull(points: np.ndarray, radius: float, blockers: np.ndarray | None,
                steps: tuple[float, ...] = RADIUS_STEPS, tet: Tetrahedra | None = None,
                pieces: bool = False) -> tuple[np.ndarray, np.ndarray] | None:
    """(vertices (V, 3), outward faces (F, 3) int32): the first closed, one-piece alpha shape of
    ``points`` (N, 3) over the probe radii ``radius * steps`` that does not span ``blockers`` (B, 3) or
    None (see ``alpha_shape``); None if there is none. ``tet``: ``Tetrahedra(points)``, when known.
    ``pieces``: when no radius gives one piece, the first closed shape in several pieces (a lobe merged
    from clusters on either side of the trunk falls apart once the wood between them is carved out).

    At one radius the carved shape lies inside the plain one: adding points to a Delaunay
    tetrahedralisation only removes tetrahedra among the old points, and carving only drops more.
    """
    reach = radius * max(steps) if len(steps) else 0.0
    tet = (tet if tet is not None else Tetrahedra(points, radius / THIN)).without(blockers, reach)
    shapes = []
    for step in steps:
        shapes.append(tet.shape(radius * step))
        if shapes[-1] is not None and is_closed_manifold(shapes[-1][1]):
            return shapes[-1]
    closed = [s for s in shapes if pieces and s is not None and is_closed_manifold(s[1], one_piece=False)]
    return closed[0] if closed else None


def plain_steps(points: np.ndarray, radius: float) -> tuple[float, ...]:
    """The ``RADIUS_STEPS`` up to the one ``lobe_hull`` used for ``points`` (all of them for a convex hull,
    which holds every alpha shape): carving within these never grows the hull."""
    return plain_hull(points, radius)[3]


def inside(vertices: np.ndarray, faces: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(M,) bool: which ``q`` (M, 3) lie inside the closed, outward-oriented mesh: a generalised winding
    number above 0.5, at a fraction of the cost (points on the surface may go either way).

    Counts the signed crossings of a ray from each point straight up (+Z): +1 through a face whose normal
    points up, -1 down. Faces whose footprint in XY misses the point cost a few comparisons. A point whose
    ray meets an edge or vertex exactly counts it once: each edge's side test is computed in one order
    (lower vertex index first) for both faces that share it, and a zero counts as the side the point
    would lie on if moved an infinitesimal step along (-eps, 1) (a symbolic perturbation).
    """
    q = np.ascontiguousarray(q, dtype=np.float64).reshape(-1, 3)
    out = np.zeros(len(q), np.int64)
    if len(q) and len(faces):
        _crossing_kernel(np.ascontiguousarray(vertices, dtype=np.float64),
                         np.ascontiguousarray(faces, dtype=np.int64), q, out)
    return out > 0


@njit(cache=True)
def _side(v: np.ndarray, a: int, b: int, x: float, y: float) -> int:  # pragma: no cover - numba
    """+1 / -1: the side of the directed edge a -> b (in XY) the point (x, y) lies on; never 0."""
    s = 1
    if a > b:
        a, b, s = b, a, -1
    dx, dy = v[b, 0] - v[a, 0], v[b, 1] - v[a, 1]
    e = dx * (y - v[a, 1]) - dy * (x - v[a, 0])
    if e == 0.0:
        e = dx if dx != 0.0 else dy
    return s if e > 0.0 else -s


@njit(cache=True)
def _crossings_of(v, f, t0, t1, flo, fhi, ftop, x, y, z) -> int:  # pragma: no cover - numba
    """Signed crossings of the ray up from (x, y, z) through faces t0:t1 (``_crossing_kernel``'s sum)."""
    total = 0
    for t in range(t0, t1):
        if x < flo[t, 0] or x > fhi[t, 0] or y < flo[t, 1] or y > fhi[t, 1] or z > ftop[t]:
            continue  # tested here, not in the call: most faces miss, and the call costs more than the test
        total += face_crossing(v, f, t, x, y, z)
    return total


@njit(cache=True)
def face_crossing(v, f, t, x, y, z) -> int:  # pragma: no cover - numba
    """+1 / -1 when the ray up from (x, y, z) crosses face ``t`` (its sign by the face's winding), else 0, for
    a point inside the face's XY box and not above its top (the callers' cheap test first)."""
    a, b, c = f[t, 0], f[t, 1], f[t, 2]
    s0 = _side(v, b, c, x, y)
    if _side(v, c, a, x, y) != s0 or _side(v, a, b, x, y) != s0:
        return 0
    w0 = (v[c, 0] - v[b, 0]) * (y - v[b, 1]) - (v[c, 1] - v[b, 1]) * (x - v[b, 0])
    w1 = (v[a, 0] - v[c, 0]) * (y - v[c, 1]) - (v[a, 1] - v[c, 1]) * (x - v[c, 0])
    w2 = (v[b, 0] - v[a, 0]) * (y - v[a, 1]) - (v[b, 1] - v[a, 1]) * (x - v[a, 0])
    w = w0 + w1 + w2
    if w != 0.0 and (w0 * v[a, 2] + w1 * v[b, 2] + w2 * v[c, 2]) / w > z:
        return s0
    return 0


@njit(cache=True)
def _crossing_kernel(v: np.ndarray, f: np.ndarray, q: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover - numba
    lo = np.zeros((f.shape[0], 2))
    hi = np.zeros((f.shape[0], 2))
    zmax = np.zeros(f.shape[0])
    for t in range(f.shape[0]):
        for k in range(2):
            lo[t, k] = min(v[f[t, 0], k], v[f[t, 1], k], v[f[t, 2], k])
            hi[t, k] = max(v[f[t, 0], k], v[f[t, 1], k], v[f[t, 2], k])
        zmax[t] = max(v[f[t, 0], 2], v[f[t, 1], 2], v[f[t, 2], 2])
    for i in range(q.shape[0]):
        out[i] = _crossings_of(v, f, 0, f.shape[0], lo, hi, zmax, q[i, 0], q[i, 1], q[i, 2])


def warm() -> None:
    """Run every compiled loop here once on a tetrahedron (see ``tetloops.warm``): ``inside``'s kernel, then the
    loops it calls, called once themselves (``face_crossing`` with the int64 faces ``hullpack`` passes it)."""
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], np.int64)
    inside(v, f, np.full((1, 3), 0.1))
    lo, hi, top = np.zeros((4, 2)), np.ones((4, 2)), np.ones(4)
    _crossings_of(v, f, 0, 4, lo, hi, top, 0.1, 0.1, 0.1)
    face_crossing(v, f, 0, 0.1, 0.1, 0.1)
    _side(v, 0, 1, 0.1, 0.1)
