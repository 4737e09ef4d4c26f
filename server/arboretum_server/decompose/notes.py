"""Notes on a decomposition: what the run did that its user may not expect (printed by ``arboretum
decompose`` after the result, and kept per scan in a library build's report)."""

from __future__ import annotations

from .options import DEFAULT_COUNTS, SPECIES_COUNTS, DecomposeOptions

LINE = 0.03
"""A cloud whose ``width_ratio`` is under this gets a note: it is a pole or a stick, not a tree."""
TREE_HEIGHTS = (0.05, 150.0)
"""Heights in metres a tree can have (the tallest measured: 116 m); a tree kept in its scan's units
(``--height 0``) outside them gets a note (a scan in millimetres reads as a 3,704 m tree)."""
ALL_LEAF = 0.95
"""A cloud with at least this fraction of foliage points gets a note: its branches have no wood to follow
(the bundled real scans measure 2-37 % foliage, the synthetic test trees 1-70 %, a tall Gaussian blob
99.8 %)."""
REPEATED = 0.01
"""A cloud of which at least this fraction of the rows repeat an earlier row exactly gets a note (merged
scans repeat points; scanners write rows without a return as (0, 0, 0)): the repeats were merged."""


def notes(options: DecomposeOptions, stats: dict) -> list[str]:
    """Every note for a decomposition run with ``options`` that gave ``stats`` (``Decomposition.stats``)."""
    return option_notes(options) + height_notes(options.height) + result_notes(options, stats)


def height_notes(height: float | None) -> list[str]:
    """A note for an output height (``--height``, metres; None: kept in the scan's units, see
    ``result_notes``) outside ``TREE_HEIGHTS``: 1e-9 makes a 1 nm tree, 1e6 a 1,000 km one. A note, not
    a refusal: a model may be wanted at any scale."""
    if height is None or TREE_HEIGHTS[0] <= height <= TREE_HEIGHTS[1]:
        return []
    what = "taller than any tree" if height > TREE_HEIGHTS[1] else "smaller than a seedling"
    return [f"--height {height:g} m is {what} (trees are {TREE_HEIGHTS[0]:g}-{TREE_HEIGHTS[1]:g} m tall): the "
            "examples are stored at that size (the default is VRTree's 0.8 m)"]


def bare_note(examples: list, named: bool = False) -> str | None:
    """The note on examples without lobes (a short main-branch stub that fed no lobe: it grows no twigs
    or leaves), None when every example has one; ``named``: their ids follow (up to 4). The wording of
    the service's ``refine.commit``."""
    bare = [e.id for e in examples if not e.structure.lobes]
    if not bare:
        return None
    ids = f" ({', '.join(bare[:4])}{', ...' if len(bare) > 4 else ''})" if named else ""
    return f"{len(bare)} of {len(examples)} examples have no lobes{ids}: they grow no twigs or leaves"


def refusal(message: str, coarse: str | None, error: Exception | None = None, doubt: str | None = None) -> str:
    """A refusal ``message`` with the file's precision note ``coarse`` (``pointio.precision_note``) when
    it has one and the refusal is about the points (not a ``preprocess.OptionError``): a float32 scan at
    UTM coordinates sits on a 0.5 m grid and is refused as "2 separate trunks" or "no trunk base", which
    names the symptom, not the cause. ``doubt`` (``upside_down_doubt``) likewise: a tree read upside
    down has no trunk base."""
    from .preprocess import OptionError, PoleError

    if isinstance(error, (OptionError, PoleError)):
        return message
    said = [message] + ([f"the file's precision may be why: {coarse}"] if coarse else []) + ([doubt] if doubt else [])
    return "; ".join(said)


_OTHER_WAY = {"z": "z-down", "y": "y-down", "z-down": "z", "y-down": "y"}


def _pass_up(way: str, build: bool) -> str:
    """How the user reads a file with ``--up way``: ``library build`` has no ``--up``."""
    return f"decompose it alone with --up {way}" if build else f"pass --up {way}"


def upside_down_note(up_asked: str, up_read: str, build: bool = False) -> str | None:
    """The note for a file ``--up auto`` found standing upside down (``up_read`` 'z-down' or 'y-down',
    ``pointio_up.guess_up``: ground at its top with a trunk on it) and turned the right way up, else
    None. ``build``: for ``library build``, which has no ``--up``."""
    if up_asked != "auto" or not up_read.endswith("-down"):
        return None
    how = _pass_up(up_read[0], build)
    return (f"--up auto found the file upside down (its ground at the top) and turned it the right way up "
            f"(--up {up_read}); to read it as written, {how}")


def upside_down_doubt(points_zup, up_read: str, build: bool = False, guess=None) -> str | None:
    """A note when the cloud as read (Z up, ``up_read``) may stand upside down but no ground says so
    (``pointio_up.trunk_on_top``: a trunk-like top over a much wider foot; a conifer's bare leader, a dead
    top or a pole beside the tree look the same, so ``--up auto`` never turns such a file), else None.
    ``guess``: ``read_points``' ``guess_up`` of a file read Z up as written, whose ground search is reused."""
    from arboretum_library.pointio_up import trunk_on_top

    if not trunk_on_top(points_zup, guess):
        return None
    other = _OTHER_WAY[up_read]
    how = _pass_up(other, build)
    return (f"the tree may stand upside down as read (--up {up_read}): its top is trunk-like over a much "
            f"wider foot and no ground tells which way is up; if the file is upside down, {how}")


def las_doubt(cloud, up_asked: str, build: bool = False) -> str | None:
    """A note when ``--up auto`` read a LAS/LAZ file Z up, as its format defines, but its shape says
    another way up as surely as a guess must be to turn other files (``pointio.auto_up``: Y up, or upside
    down on its ground); else None. ``cloud`` as ``read_points`` gave it."""
    from arboretum_library.pointio import auto_up, z_up_by_format
    from arboretum_library.pointio_up import guess_up

    if not z_up_by_format(cloud.source, up_asked):
        return None
    if (way := auto_up(guess_up(cloud.points))) == "z":
        return None
    return (f"the LAS file is read Z up, as its format defines, but its shape says {way} "
            f"(the way --up auto reads other files): if it is, {_pass_up(way, build)}")


def up_doubts(cloud, up_asked: str, build: bool = False) -> str | None:
    """``las_doubt`` and ``upside_down_doubt`` of ``cloud`` as one note, or None."""
    guess = cloud.up_guess if cloud.up_axis == "z" else None  # its ground search, along Z as read
    said = [las_doubt(cloud, up_asked, build), upside_down_doubt(cloud.points, cloud.up_axis, build, guess)]
    return "; ".join(n for n in said if n) or None


def up_guess_flat(points_zup, up_asked: str, up_read: str) -> str | None:
    """Why a cloud read with ``--up auto`` lies at one height when the guess turned it (``up_read``
    'y'), yet the file as written does not (its Z spreads): a vertical wall in a Z-up file reads as Y up
    (``pointio.guess_up_axis``) and then lies flat. The message, else None. ``points_zup`` (N, 3) as read."""
    import numpy as np

    if up_asked != "auto" or up_read not in ("y", "y-down"):
        return None
    pts = np.asarray(points_zup, dtype=np.float64)
    pts = pts[np.isfinite(pts).all(axis=1)]
    if len(pts) == 0 or np.ptp(pts[:, 2]) > 0:
        return None
    file_z = np.ptp(pts[:, 1])  # yup_to_zup: the file's z is -y as read
    if file_z <= 0:
        return None
    return (f"--up auto guessed the file is Y up and turned it, which lays all its points at one height; "
            f"as written they spread {file_z:.3g} along Z")


def result_notes(options: DecomposeOptions, stats: dict) -> list[str]:
    """Notes for what the decomposition could not meet (counts), then ``scan_notes``. A figure missing
    from ``stats`` gives no note."""
    n_m, n_l = options.counts()
    out = []
    if stats.get("main_branches", n_m) < n_m:
        out.append(f"{stats['main_branches']} main branches found, {n_m} asked: the other candidate paths "
                   "merged into them (Algorithm 1)")
    if stats.get("lobes", n_l) < n_l:
        out.append(f"{stats['lobes']} lobes made, {n_l} asked: too few foliage points")
    h = stats.get("height")
    if options.height is None and h is not None and not TREE_HEIGHTS[0] <= h <= TREE_HEIGHTS[1]:
        out.append(f"the tree is {h:.4g} scan units tall, kept as metres (--height 0): "
                   f"{'taller than any tree' if h > TREE_HEIGHTS[1] else 'smaller than a seedling'}; "
                   "if the scan is in other units, pass --height METRES")
    return out + scan_notes(stats)


def scan_notes(stats: dict) -> list[str]:
    """Notes on the cloud itself (repeated points, all foliage, a straight line, trunk-like columns away
    from the root), which refinement does not change. A figure missing from ``stats`` gives no note."""
    out = []
    if repeated := repeated_note(stats.get("repeated")):
        out.append(repeated)
    if stats.get("strays"):
        n = stats["strays"]
        out.append(f"{n} stray point{'s' if n > 1 else ''} left out: alone, or in small groups below or above "
                   "the tree, over a tenth of its height from the rest of the cloud (scanner noise, a bird?); "
                   "they would have set the trunk base or the height")
    if stats.get("apart"):
        n = stats["apart"]
        out.append(f"{n} point{'s' if n > 1 else ''} under the tree left out: a small piece apart from the trunk's "
                   "foot (a clump, a stump or a bush beside it?) that would have been taken for the trunk base; "
                   "if it was the trunk's own foot, the root now sits higher than it should")
    off = stats.get("labels") == "leaf-off"  # declared leafless: the guess's "leaf" is fine wood, routed alike
    leaf = stats.get("fine_wood_points" if off else "leaf_points", 0) / max(stats.get("points", 0), 1)
    if leaf >= ALL_LEAF:
        what = ("read as fine, space-filling wood and almost none as stems: the branches were routed through it"
                if off else f"are foliage ({stats['labels']} labels) and almost none wood: the branches were "
                "routed through foliage")
        out.append(f"{leaf:.1%} of the points {what} and are a guess (is this one tree, with its trunk?)")
    if stats.get("width_ratio", 1.0) < LINE:
        out.append(f"the cloud is nearly a straight line (it spreads {stats['width_ratio']:.1%} as wide as it "
                   "is long): there is no crown to decompose, and the branches lie along that line")
    cols = stats.get("trunk_columns") or []
    if cols:
        where = "; ".join(f"foot at x {c['foot'][0]:.7g}, y {c['foot'][1]:.7g}, {c['distance']:.3g} from the trunk "
                          f"base and {c['rise']:.3g} higher" for c in cols[:3])
        out.append(f"{len(cols)} trunk-like column{'s' if len(cols) > 1 else ''} away from the trunk base "
                   f"({where}{'; ...' if len(cols) > 3 else ''}; scan units, Z up): another tree? It was "
                   "decomposed as part of this one; crop the scan to one tree if it is not")
    return out


def repeated_note(rep: dict | None) -> str | None:
    """The note on the exact duplicates merged (``repeats.Repeats.as_stats``) when they make up
    ``REPEATED`` of the rows or more or their pile was left out, naming the spot when one point holds
    most of them."""
    if not rep or not (rep["merged"] >= REPEATED * max(rep["rows"], 1) or rep.get("left_out")):
        return None
    if rep["most"] - 1 >= rep["merged"] / 2 or rep.get("left_out"):
        what = f"{rep['most']:,} rows hold the point ({', '.join(f'{v:.7g}' for v in rep['at'])}), scan units"
        if not any(rep["at"]):
            what += " (no-return rows of the scanner?)"
        if rep.get("left_out"):
            what += f"; it lies {rep['apart']:.3g} from every other point and was left out"
    elif rep["fewest"] == rep["most"]:
        what = f"{rep['repeated']:,} points are given {rep['most']} times each"
    else:
        what = f"{rep['repeated']:,} points are given {rep['fewest']} to {rep['most']:,} times"
    return f"{rep['merged']:,} repeated points merged, each point is used once: {what}"


def option_notes(options: DecomposeOptions) -> list[str]:
    """What the run assumes that the user may not expect (printed with the result)."""
    missing = [f"{name} = {v}" for name, v, given in (("N_m", DEFAULT_COUNTS[0], options.n_main),
                                                       ("N_l", DEFAULT_COUNTS[1], options.n_lobes)) if given is None]
    if options.species in SPECIES_COUNTS or options.species == "unknown" or not missing:
        return []
    return [f"species '{options.species}' is not in VRTree Table 2 ({', '.join(SPECIES_COUNTS)}): "
            f"{', '.join(missing)} (the table's medians)"]
