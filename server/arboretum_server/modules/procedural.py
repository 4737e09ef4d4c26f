"""A procedural default module set: 23 branch modules and 2 trunks as closed swept-tube meshes.

Lengths in metres at scale 1: branch modules are 0.35-2.2 m long with base radii 0.4-12 cm (seven twigs and
whips of 1.5 cm or less, so that thin parents can still carry children at s >= s_l; four slowly tapering shoots
and limbs, so that radius lasts over several layers); trunks are 3.5-4 m with base radii 22-25 cm. The generator's random draws only jitter lengths and bend directions.
"""

from __future__ import annotations

import numpy as np

from arboretum_library.geometry import axis_angle_matrix

from ._tube import Limb, sweep_limbs
from .moduleset import Module, ModuleSet, make_module

Z = np.array([0.0, 0.0, 1.0])


def _tilt(direction: np.ndarray, angle_deg: float, azimuth_deg: float) -> np.ndarray:
    """``direction`` (3,) tilted by ``angle_deg`` towards the azimuth ``azimuth_deg`` about it."""
    d = direction / np.linalg.norm(direction)
    side = np.cross(d, [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 1.0, 0.0])
    side = axis_angle_matrix(d, np.radians(azimuth_deg)) @ (side / np.linalg.norm(side))
    return axis_angle_matrix(np.cross(d, side), np.radians(angle_deg)) @ d


def _arc(start, direction, length, bend, n=8):
    """(n, 3) points of a gently bent centre line; ``bend`` (3,) is the sideways offset at the end."""
    s = np.concatenate([[0.0, 0.01], np.linspace(0.0, 1.0, n)[1:]])[
        :, None
    ]  # short straight lead-in
    return start + s * length * direction + s**2 * bend


def _grow(limbs: list[Limb], spec: dict, start, direction, parent: int, r0: float, rng) -> None:
    """Append the limb described by ``spec`` and, recursively, its children (attached at its end)."""
    length = spec["length"] * rng.uniform(0.92, 1.08)
    bend_dir = _tilt(direction, 90.0, rng.uniform(0, 360))
    pts = _arc(
        start, direction, length, spec.get("bend", 0.0) * length * bend_dir, n=spec.get("n", 8)
    )
    r1 = r0 * spec.get("taper", 0.8)
    limbs.append(Limb(pts, np.linspace(r0, r1, len(pts)), parent))
    me = len(limbs) - 1
    end_dir = pts[-1] - pts[-2]
    end_dir /= np.linalg.norm(end_dir)
    az0 = rng.uniform(0, 360)
    for k, child in enumerate(spec.get("children", [])):
        d = _tilt(end_dir, child["angle"], az0 + child.get("azimuth", 180.0 * k))
        _grow(limbs, child, pts[-1], d, me, r1 * child.get("radius", 0.8), rng)


def _tip(length, angle=0.0, bend=0.0, azimuth=None, radius=0.85, taper=0.55):
    spec = {"length": length, "angle": angle, "bend": bend, "radius": radius, "taper": taper}
    if azimuth is not None:
        spec["azimuth"] = azimuth
    return spec


SPECS: dict[str, tuple[float, dict]] = {
    "branch_00_single": (0.045, {"length": 1.0, "taper": 0.45}),
    "branch_01_curved": (0.045, {"length": 1.1, "bend": 0.25, "taper": 0.45}),
    "branch_02_fork": (0.05, {"length": 0.5, "children": [_tip(0.5, 28), _tip(0.45, 28)]}),
    "branch_03_wide_fork": (0.055, {"length": 0.4, "children": [_tip(0.6, 45), _tip(0.55, 45)]}),
    "branch_04_side": (
        0.05,
        {"length": 0.45, "children": [_tip(0.6, 8, radius=0.95), _tip(0.4, 50, radius=0.7)]},
    ),
    "branch_05_two_sides": (
        0.055,
        {
            "length": 0.35,
            "children": [
                {
                    "length": 0.35,
                    "angle": 6,
                    "radius": 0.95,
                    "taper": 0.8,
                    "children": [_tip(0.4, 6, radius=0.95), _tip(0.3, 55, radius=0.7)],
                },
                _tip(0.35, 50, radius=0.7),
            ],
        },
    ),
    "branch_06_multi_fork": (
        0.06,
        {
            "length": 0.45,
            "children": [
                _tip(0.5, 30, azimuth=0),
                _tip(0.45, 30, azimuth=120),
                _tip(0.5, 30, azimuth=240),
            ],
        },
    ),
    "branch_07_long_thin": (0.035, {"length": 1.4, "bend": 0.15, "taper": 0.4, "n": 10}),
    "branch_08_short_stubby": (0.06, {"length": 0.3, "children": [_tip(0.3, 35), _tip(0.3, 35)]}),
    "branch_10_scaffold": (
        0.08,
        {
            "length": 0.7,
            "bend": 0.1,
            "taper": 0.85,
            "children": [_tip(0.7, 12, radius=0.9, taper=0.6), _tip(0.5, 40, radius=0.7)],
        },
    ),
    "branch_11_thick_single": (0.075, {"length": 1.2, "bend": 0.1, "taper": 0.55, "n": 10}),
    "branch_09_curved_side": (
        0.045,
        {
            "length": 0.55,
            "bend": 0.2,
            "children": [_tip(0.5, 10, bend=0.2, radius=0.95), _tip(0.35, 60, radius=0.65)],
        },
    ),
    "branch_12_twig_fork": (0.018, {"length": 0.3, "children": [_tip(0.3, 30), _tip(0.25, 40)]}),
    "branch_13_twig": (0.015, {"length": 0.6, "bend": 0.2, "taper": 0.5}),
    "trunk_00_straight": (0.25, {"length": 3.5, "taper": 0.5, "n": 12}),
    "trunk_01_leaning": (0.22, {"length": 4.0, "bend": 0.06, "taper": 0.45, "n": 14}),
    # added after the trunks so that the older modules' random draws (and meshes) are unchanged
    # thin twigs and whips: thin parents (r_p down to ~2 mm) can still carry a child at s >= s_l
    "branch_14_fine_twig": (0.009, {"length": 0.45, "bend": 0.2, "taper": 0.5}),
    "branch_15_fine_fork": (0.008, {"length": 0.22, "children": [_tip(0.25, 30), _tip(0.2, 40)]}),
    "branch_16_hair_twig": (0.0055, {"length": 0.35, "bend": 0.15, "taper": 0.5}),
    "branch_17_whip": (0.007, {"length": 1.0, "bend": 0.15, "taper": 0.75}),
    "branch_18_fine_whip": (0.004, {"length": 0.6, "bend": 0.15, "taper": 0.75}),
    # slowly tapering shoots and limbs: radius is kept over several layers, so growth reaches far
    "branch_19_shoot": (0.03, {"length": 1.0, "bend": 0.12, "taper": 0.7}),
    "branch_20_slim_shoot": (0.012, {"length": 0.7, "bend": 0.15, "taper": 0.7}),
    "branch_21_limb": (
        0.12,
        {
            "length": 1.2,
            "bend": 0.08,
            "taper": 0.8,
            "children": [_tip(1.0, 10, radius=0.9, taper=0.6), _tip(0.7, 40, radius=0.7)],
        },
    ),
    "branch_22_long_limb": (
        0.1,
        {
            "length": 1.6,
            "bend": 0.06,
            "taper": 0.8,
            "n": 10,
            "children": [_tip(0.6, 10, radius=0.95, taper=0.7), _tip(0.5, 45, radius=0.6)],
        },
    ),
}


def make_default_module_set(rng: np.random.Generator) -> ModuleSet:
    """The default set: the modules of ``SPECS`` swept into closed meshes, skeletons extracted."""
    modules: list[Module] = []
    for name, (r0, spec) in SPECS.items():
        limbs: list[Limb] = []
        _grow(limbs, spec, np.zeros(3), Z, -1, r0, rng)
        verts, faces = sweep_limbs(limbs, sides=12 if name.startswith("trunk") else 8)
        modules.append(make_module(name, verts, faces))
    return ModuleSet(tuple(modules))


README = """# Default branch and trunk modules

Generated by `arboretum_server.modules.procedural.write_default_module_set` with
`numpy.random.default_rng({seed})`: {count} closed swept-tube meshes (OBJ, Z up, metres, base at the
origin pointing +Z). Files named `trunk_*` are trunks; the others are branch modules (single, curved,
forked, wide fork, side branches, three-way fork, long thin, stubby, scaffold, twigs,
fine twigs, whips, shoots, limbs). Base radii span 4 mm to 12 cm, so thin parents can carry thin children.
Regenerate with:

    .venv/bin/python -c "from arboretum_server.modules.procedural import write_default_module_set as w; w()"

Licence: generated by Arboretum, same licence as the project.
"""


def write_default_module_set(folder=None, seed: int = 7):
    """Write the default set as ``folder``/*.obj (default: assets/modules/default) plus a README."""
    from pathlib import Path

    from arboretum_library.assets import assets_dir

    from .moduleset import save_module_set

    folder = Path(folder) if folder is not None else assets_dir() / "modules" / "default"
    modules = make_default_module_set(np.random.default_rng(seed))
    paths = save_module_set(modules, folder, note=f"default module set, seed {seed}")
    (folder / "README.md").write_text(README.format(seed=seed, count=len(modules.modules)))
    return paths
