"""Plausible HBL records for tests: examples and whole trees built from a seeded Generator.

Import as ``from factories import make_example`` (pytest puts tests/ on sys.path through conftest.py)
or ``from tests.factories import make_example`` (when the repository root is on sys.path).
Same Generator state, same record, on every machine.
"""

from __future__ import annotations

import contextlib
import dataclasses
import fcntl
import functools
from pathlib import Path

import numpy as np

from arboretum_library.codec import flatten
from arboretum_library.descriptors import describe, tags_for
from arboretum_library.model import HBL, LEAF, WOOD, Branch, Example, Level, Lobe, Provenance

_OCTA_DIRS = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
_OCTA_FACES = np.array(
    [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]], np.int32
)
"""Outward-facing triangles of the unit octahedron ``_OCTA_DIRS``."""


def main_polyline(rng: np.random.Generator, base: np.ndarray, length: float, curved: bool,
                  n: int = 9) -> np.ndarray:
    """(n, 3) polyline from ``base`` rising in Z: straight (mm jitter) or bent through about 90 deg."""
    s = np.linspace(0.0, 1.0, n)
    if curved:
        radius = length / (np.pi / 2)
        heading = rng.uniform(0, 2 * np.pi)
        out = radius * (1 - np.cos(s * np.pi / 2))
        pts = np.c_[out * np.cos(heading), out * np.sin(heading), radius * np.sin(s * np.pi / 2)]
    else:
        pts = np.c_[rng.normal(0, 1e-3, n), rng.normal(0, 1e-3, n), s * length]
        pts[0, :2] = 0.0
    return pts + base


def make_lobe(rng: np.random.Generator, centre: np.ndarray, radius: float, n_points: int,
              branch: int) -> Lobe:
    """A lobe of ``n_points`` members in a ball around ``centre`` and an octahedral hull enclosing it."""
    dirs = rng.normal(size=(n_points, 3))
    dirs /= np.maximum(np.linalg.norm(dirs, axis=1, keepdims=True), 1e-9)
    members = centre + dirs * radius * rng.uniform(0, 0.55, (n_points, 1))
    hull = centre + _OCTA_DIRS * radius * 1.8
    return Lobe(members, hull, _OCTA_FACES, centre, branch)


def _secondary(rng: np.random.Generator, parent: int, parent_pts: np.ndarray, vertex: int,
               reach: float) -> tuple[Branch, np.ndarray]:
    """A secondary branch from ``parent_pts[vertex]`` outwards and upwards; returns it and its tip."""
    angle = rng.uniform(0, 2 * np.pi)
    start = parent_pts[vertex]
    tip = start + reach * np.array([np.cos(angle), np.sin(angle), 0.5])
    pts = start + np.linspace(0, 1, 4)[:, None] * (tip - start)
    return Branch(pts, np.linspace(0.015, 0.005, 4), parent, vertex, Level.SECONDARY), tip


def _wood_points(rng: np.random.Generator, branches: list[Branch], n: int) -> np.ndarray:
    """``n`` points scattered (1 cm) around random vertices of ``branches``."""
    verts = np.concatenate([b.points for b in branches])
    pick = rng.integers(0, len(verts), n)
    return verts[pick] + rng.normal(0, 0.01, (n, 3))


def _structure(rng: np.random.Generator, mains: list[Branch], n_lobes: int, n_points: int) -> HBL:
    """Attach ``n_lobes`` secondary branches with lobes to ``mains`` (cycled) and scatter points."""
    branches = list(mains)
    lobes = []
    leaf_n = int(n_points * 0.7) if n_lobes else 0
    per_lobe = np.diff(np.linspace(0, leaf_n, n_lobes + 1).astype(int))
    for k in range(n_lobes):
        parent = k % len(mains)
        pts = mains[parent].points
        vertex = 2 + (k // len(mains) * 2 + k) % (len(pts) - 2)
        sec, tip = _secondary(rng, parent, pts, vertex, rng.uniform(0.25, 0.45))
        branches.append(sec)
        lobes.append(make_lobe(rng, tip, rng.uniform(0.08, 0.15), int(per_lobe[k]), len(branches) - 1))
    wood = _wood_points(rng, branches, n_points - leaf_n)
    leaves = [lb.points for lb in lobes] or [np.zeros((0, 3))]
    points = np.concatenate([wood, *leaves])
    labels = np.r_[np.full(len(wood), WOOD), np.full(len(points) - len(wood), LEAF)].astype(np.uint8)
    return HBL(mains[0].points[0], branches, lobes, points, labels)


def make_example(rng: np.random.Generator, *, id: str | None = None, n_lobes: int = 4,
                 curved: bool = False, species: str = "apple", source: str = "test.xyz",
                 n_points: int = 200) -> Example:
    """One example: a main branch (straight, or bent ~90 deg when ``curved``) with ``n_lobes`` lobes.

    Descriptors come from ``describe`` and tags from ``tags_for``, so they agree with the library's.
    """
    ex_id = id if id is not None else f"ex-{int(rng.integers(0, 10**8)):08d}"
    base = np.array([0.0, 0.0, 0.0])
    pts = main_polyline(rng, base, rng.uniform(1.2, 1.8), curved)
    main = Branch(pts, np.linspace(0.04, 0.015, len(pts)))
    structure = _structure(rng, [main], n_lobes, n_points)
    d = describe(structure)
    sha = f"{int(rng.integers(0, 2**62)):064x}"
    prov = Provenance(source, sha, species, {"N_m": 10, "K": 12, "alpha": 0.1})
    return Example(ex_id, structure, prov, d, tags_for(d))


def make_hbl(rng: np.random.Generator, n_main: int = 3, n_lobes: int = 8, n_points: int = 400) -> HBL:
    """A whole tree: a trunk, ``n_main - 1`` further main branches off it, ``n_lobes`` lobes."""
    trunk_pts = main_polyline(rng, np.zeros(3), 3.0, False, n=12)
    mains = [Branch(trunk_pts, np.linspace(0.12, 0.03, len(trunk_pts)))]
    for k in range(1, n_main):
        vertex = 4 + (k * 3) % (len(trunk_pts) - 5)
        pts = main_polyline(rng, trunk_pts[vertex], 1.2, bool(k % 2))
        mains.append(Branch(pts, np.linspace(0.05, 0.015, len(pts)), 0, vertex, Level.MAIN))
    return _structure(rng, mains, n_lobes, n_points)


def make_library(root, n: int, seed: int = 5, **example_kwargs):
    """A library at ``root`` holding ``make_example``s ``ex-0`` .. ``ex-{n-1}`` (``n_lobes`` 3 unless
    given); returns ``root``."""
    from arboretum_library.store import Library

    rng = np.random.default_rng(seed)
    with Library.open(root, create=True) as lib:
        for i in range(n):
            lib.add(make_example(rng, id=f"ex-{i}", **{"n_lobes": 3, **example_kwargs}))
    return root


def assert_examples_equal(a: Example, b: Example) -> None:
    """Every field equal and every array equal bit for bit (same dtype, shape and bytes)."""
    meta_a, arrays_a = flatten(a)
    meta_b, arrays_b = flatten(b)
    assert meta_a == meta_b
    assert sorted(arrays_a) == sorted(arrays_b)
    for key, arr in arrays_a.items():
        other = arrays_b[key]
        assert arr.dtype == other.dtype and arr.shape == other.shape, key
        assert arr.tobytes() == other.tobytes(), key
    assert dataclasses.asdict(a.descriptors) == dataclasses.asdict(b.descriptors)


@contextlib.contextmanager
def held_lock(path: Path):
    """Hold LIB/.lock as another writing process would (a separate open file, so flock excludes this
    process's own Library too)."""
    with open(Path(path) / ".lock", "a+b") as f:
        fcntl.flock(f.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f.fileno(), fcntl.LOCK_UN)


@contextlib.contextmanager
def held_folder(folder: Path):
    """Make ``folder`` and hold its ``flock`` on another descriptor, as another ``keys generate`` would;
    yields a function that releases it early (it is released on exit otherwise)."""
    import os

    folder.mkdir()
    fd = os.open(folder, os.O_RDONLY)
    fcntl.flock(fd, fcntl.LOCK_EX)
    closed: list[bool] = []

    def release() -> None:
        if not closed:
            closed.append(True)
            os.close(fd)

    try:
        yield release
    finally:
        release()


@contextlib.contextmanager
def serving(server):
    """Run ``server`` (a ``service.socket.Server``) on a daemon thread; stop it and wait for the thread on
    exit (at most 10 s), asserting it ended."""
    import threading

    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield server
    finally:
        server.stop_event.set()
        thread.join(10)
    assert not thread.is_alive()


@contextlib.contextmanager
def dispatcher(state: Path, library: Path):
    """An in-process service: a ``Dispatcher`` over a ``Context`` with sessions in ``state`` and the library
    at ``library``, closed on exit."""
    from arboretum_server.service.context import Context
    from arboretum_server.service.dispatch import Dispatcher
    from arboretum_server.service.sessions import Sessions

    ctx = Context(Sessions(state), library)
    try:
        yield Dispatcher(ctx)
    finally:
        ctx.close()


def reply_of(d, req):
    """The reply of the ``Dispatcher`` ``d`` to ``req``, asserted to be the request's reply type (no Error)."""
    reply = d.run(req)
    assert isinstance(reply, req.REPLY), reply
    return reply


def run_then_kill(script: str, root: Path, delay: float, on_ready=None) -> None:
    """Run the writer ``script`` (a test file run as a script) on the library ``root`` with tests/ on its
    path; once it prints 'ready', call ``on_ready()`` (if given), let it write for ``delay`` seconds, then
    SIGKILL it and wait for it."""
    import os
    import signal
    import subprocess
    import sys
    import time

    here = str(Path(__file__).resolve().parent)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [here, os.environ.get("PYTHONPATH")]))}
    proc = subprocess.Popen([sys.executable, script, str(root)], stdout=subprocess.PIPE, env=env)
    try:
        assert proc.stdout.readline().strip() == b"ready"
        if on_ready is not None:
            on_ready()
        time.sleep(delay)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        proc.stdout.close()


def build_then_signal(folder: Path, scans: int, points: int, stop) -> tuple[int, str, Path, list[Path]]:
    """``library build`` of ``scans`` synthetic scans of ``points`` points into ``folder``/lib, 2 workers,
    in its own session; once its first examples are stored (folders in ``examples/`` and no write under way
    in ``.tmp/``: a folder renamed in before its catalog commit is rolled back by a signal, and the build
    then removes the library it created), ``stop(proc)`` (send a signal). Returns (exit
    code, stderr with carriage returns as newlines, the library, the scans)."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from arboretum_server.batch.synthetic import synthetic_scans

    paths = synthetic_scans(folder / "s", scans, points=points)
    lib = folder / "lib"
    argv = [sys.executable, "-m", "arboretum_library.cli", "library", "build", *map(str, paths), "--library",
            str(lib), "--workers", "2", "--points", str(points)]
    proc = subprocess.Popen(argv, start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            env={**os.environ, "OMP_WAIT_POLICY": "PASSIVE"})
    try:
        t0 = time.monotonic()
        def stored() -> bool:
            ex, tmp = lib / "examples", lib / ".tmp"
            return ex.is_dir() and any(ex.iterdir()) and tmp.is_dir() and not any(tmp.iterdir())

        while not stored():
            assert proc.poll() is None and time.monotonic() - t0 < 120
            time.sleep(0.1)
        stop(proc)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    return proc.returncode, err.decode().replace("\r", "\n"), lib, paths


TOY_DRAFT_OPTIONS = {"n_main": 3, "n_lobes": 5, "points": 4000}
"""Options of the refinement drafts the service tests open on the toy tree (3 main branches, 5 lobes)."""


def service_folders(tmp_path: Path) -> tuple[Path, Path]:
    """(state folder, library) for ``dispatcher``, the library created empty."""
    from arboretum_library.store import Library

    Library.open(tmp_path / "lib", create=True).close()
    return tmp_path / "state", tmp_path / "lib"


def toy_cloud(seed: int = 2):
    """(points (4000, 3), labels) of the toy tree's toy scan."""
    from arboretum_server.decompose.toytree import toy_scan, toy_truth

    return toy_scan(toy_truth(), n=4000, seed=seed)


def open_toy_draft(server, name: str = "toy", options: dict | None = None, shift=(0.0, 0.0, 0.0)) -> str:
    """A new session of ``server`` with a refinement draft of the toy tree open (``TOY_DRAFT_OPTIONS``
    unless ``options``; the points moved by ``shift``); its id."""
    from arboretum_library import protocol as P

    pts, labels = toy_cloud()
    sid = reply_of(server, P.SessionNew()).session
    reply_of(server, P.RefineOpen(session=sid, points=pts + shift, labels=labels, name=name,
                                  options=TOY_DRAFT_OPTIONS if options is None else options))
    return sid


def library_ids(server) -> list[str]:
    """The ids in ``server``'s library, sorted."""
    from arboretum_library import protocol as P

    return sorted(e["id"] for e in reply_of(server, P.LibraryList()).entries)


def float32_ply(path: Path, pts: np.ndarray) -> Path:
    """``pts`` (N, 3) written to ``path`` as a binary float32 PLY (x y z only): at UTM magnitudes the
    values sit on a 0.5 m grid."""
    body = np.asarray(pts, dtype="<f4")
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(body)}\n"
            "property float x\nproperty float y\nproperty float z\nend_header\n")
    path.write_bytes(head.encode() + body.tobytes())
    return path


def hbl_arrays(d) -> list:
    """Every array of decomposition ``d``'s HBL (points, labels, branches, lobes and hulls), in order: two
    decompositions are the same when these are equal one by one."""
    import numpy as np

    hbl = d.hbl
    out = [hbl.points, hbl.labels]
    for b in hbl.branches:
        out += [b.points, b.radii, np.array([b.parent, b.parent_vertex])]
    for lb in hbl.lobes:
        out += [lb.points, lb.hull_vertices, lb.hull_faces, lb.centre, np.array([lb.branch])]
    return out


def toy_tree_scan() -> tuple[np.ndarray, float]:
    """The toy tree's leaf-off toy scan (seed 5) and its height: the ground tests' tree."""
    from arboretum_server.decompose.toytree import toy_scan, toy_truth

    pts, _ = toy_scan(toy_truth(), leaf_fraction=0.0, seed=5)
    return pts, float(np.ptp(pts[:, 2]))


def ground_disc(tree: tuple[np.ndarray, float], surface, n: int, radius: float = 1.5, seed: int = 0) -> np.ndarray:
    """``n`` ground points on a disc ``radius`` heights round the trunk of ``tree`` (``toy_tree_scan``), at
    ``surface(x, y)`` (in heights) above the tree's lowest point."""
    pts, h = tree
    rng = np.random.default_rng(seed)
    r, a = radius * h * np.sqrt(rng.uniform(0, 1, n)), rng.uniform(0, 2 * np.pi, n)
    x, y = r * np.cos(a), r * np.sin(a)
    return np.c_[x, y, pts[:, 2].min() + h * surface(x / h, y / h)]


def las_file(path: Path, pts: np.ndarray, scale: float = 1e-4) -> Path:
    """``pts`` (N, 3) written to ``path`` (.las or .laz), point format 3, ``scale`` metres per unit."""
    import laspy

    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales, header.offsets = np.full(3, scale), pts.min(axis=0)
    las = laspy.LasData(header)
    las.x, las.y, las.z = pts[:, 0], pts[:, 1], pts[:, 2]
    las.write(str(path))
    return path


def layered_tree(seed: int, n_trunk: int, slope: float, thick: float = 0.05) -> np.ndarray:
    """A tree 20 tall with no ground: a trunk 0.15 wide seen by ``n_trunk`` points through five dense flat
    branch layers of 3,000 points at 4, 7, 10, 13 and 16, rising ``slope`` outwards, ``thick`` (sd) thick."""
    rng = np.random.default_rng(seed)
    a, z = rng.uniform(0, 2 * np.pi, n_trunk), rng.uniform(0, 20, n_trunk)
    parts = [np.c_[0.15 * np.cos(a), 0.15 * np.sin(a), z]]
    for level in (4, 7, 10, 13, 16):
        reach = 2.5 * (20 - level) / 16
        r, b = reach * np.sqrt(rng.uniform(0.02, 1, 3000)), rng.uniform(0, 2 * np.pi, 3000)
        parts.append(np.c_[r * np.cos(b), r * np.sin(b), level + slope * r + rng.normal(0, thick, 3000)])
    return np.concatenate(parts)


def trunk_on_disc(rng: np.random.Generator) -> np.ndarray:
    """A 10 m trunk (2,000 points, radius 0.1) with a crown (6,000) over a ground disc 3 in radius
    (8,000 points first), drawn from ``rng``."""
    a, z = rng.uniform(0, 2 * np.pi, 2000), rng.uniform(0, 10, 2000)
    trunk = np.c_[0.1 * np.cos(a), 0.1 * np.sin(a), z]
    r, b = 3 * np.sqrt(rng.uniform(0, 1, 8000)), rng.uniform(0, 2 * np.pi, 8000)
    disc = np.c_[r * np.cos(b), r * np.sin(b), rng.normal(0, 0.01, 8000)]
    crown = np.c_[rng.normal(0, 1, (6000, 2)), rng.uniform(4, 10, 6000)]
    return np.r_[disc, trunk, crown]


def strewn(pts: np.ndarray, share: float, seed: int, wider: float = 0.2) -> np.ndarray:
    """``share`` of the points of ``pts`` (N, 3) strewn uniformly over a box ``wider`` (a fraction) than
    it each way."""
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = wider * (hi - lo)
    return np.random.default_rng(seed).uniform(lo - pad, hi + pad, (int(share * len(pts)), 3))


def prepared_root(pts: np.ndarray) -> np.ndarray:
    """``prepare``'s trunk base of ``pts`` (N, 3) with the default options, in the scan's frame."""
    from arboretum_server.decompose.options import DecomposeOptions
    from arboretum_server.decompose.preprocess import prepare

    o = DecomposeOptions()
    return prepare(pts, o, np.random.default_rng(o.seed)).root_scan


@functools.cache
def real_scan(key: str) -> tuple[np.ndarray, np.ndarray]:
    """(points (N, 3), ``prepared_root``) of the bundled real scan whose file name starts with ``key``
    ('01', '06', '07', '10'); cached: do not change the arrays."""
    scans = Path(__file__).resolve().parents[1] / "assets" / "scans"
    pts = np.loadtxt(next(scans.glob(f"*/{key}*.xyz")))[:, :3]
    return pts, prepared_root(pts)


def stubbed_pole(n: int, seed: int = 0) -> np.ndarray:
    """A pole 5 m tall and 1 cm thick with three 0.25 m stubs holding 3 % of the points each: it is let
    through (a pole alone is refused since session 28) and gets the straight-line note (width ratio 0.023)."""
    rng = np.random.default_rng(seed)
    pole = np.c_[rng.normal(0, 0.01, (n, 2)), rng.uniform(0, 5, n)]
    d = rng.uniform(0, 0.25, (3, n // 30))
    return np.vstack([pole, *(np.c_[r * np.cos(a), r * np.sin(a), z + 0.5 * r]
                              for r, a, z in zip(d, (0, 2.1, 4.2), (2, 3, 4)))])
