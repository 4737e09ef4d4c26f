"""Freestyle generation (VRTree 4.2, Fig. 7): new trees of several species assembled from example libraries.

Libraries: three harmonic species (pine, walnut, eucalyptus) grown by ``grow_species``, scanned by the
virtual scanner and decomposed with their species' N_m / N_l, and the real scan 07 (decomposed as
walnut). Each new tree takes its species' trunk example (the longest main branch, at its original
pose) and places every other example of the library on it turned by a random angle about the trunk
and scaled by a random factor (a stand-in for the user's freehand placement); recombination joins
each to the trunk. A fourth tree mixes the real library and the walnut one. Every tree is grown
(space colonisation in the lobes) and pictured side by side.

    python examples/01_freestyle.py --out out/freestyle --seed 0
"""

from __future__ import annotations

import time

import numpy as np
from _common import (
    about_base,
    camera_for,
    emit,
    grown_items,
    hbl_figures,
    labelled,
    library,
    parse_args,
    real_scan,
    render,
    save,
    side_by_side,
    source,
    structure_items,
    synth_scan,
)

SYNTH = ("pine", "walnut", "eucalyptus")
SIZE = (320, 480)


def libraries(seed: int) -> dict[str, list]:
    """species -> examples (harmonic species from their scans, 'real' from scan 07)."""
    libs = {}
    for k, sp in enumerate(SYNTH):
        pts, labels = synth_scan(sp, seed + 1 + k)
        libs[sp] = library(pts, labels, sp, sp, seed)[1]
    pts, _ = real_scan("07_itsme_buttressed_tree_1")
    libs["real"] = library(pts, None, "walnut", "scan07", seed)[1]
    return libs


def new_tree(trunk, branches: list, rng: np.random.Generator):
    """An Assembly: ``trunk`` at its original pose, each of ``branches`` turned and scaled at random."""
    from arboretum_library.assembly import Assembly
    from arboretum_server.assembly import ops

    get = source([trunk], branches)
    a, _ = ops.add_example(Assembly(), get, trunk.id, np.eye(4), 1.0, "trunk")
    for k, ex in enumerate(branches):
        turn, scale = float(rng.uniform(0, 360)), float(rng.uniform(0.8, 1.2))
        a, _ = ops.add_example(a, get, ex.id, about_base(ex, turn, scale), scale, f"b{k}")
    return a, get


def main() -> None:
    args = parse_args(__doc__)
    t0 = time.perf_counter()
    from arboretum_server.assembly.world import assembly_to_hbl

    rng = np.random.default_rng(args.seed)
    libs = libraries(args.seed)
    plans = {sp: (libs[sp][0], libs[sp][1:]) for sp in SYNTH}
    plans["mixed"] = (libs["real"][0], libs["real"][1:4] + libs["walnut"][1:5])
    trees, grown, structs = {}, [], []
    for name, (trunk, branches) in plans.items():
        a, get = new_tree(trunk, branches, rng)
        hbl = assembly_to_hbl(a, get)
        items, counts = grown_items(hbl, args.seed)
        fig = hbl_figures(hbl) | counts | {"examples": len(a.placements), "merges": len(a.merges),
                                            "library": len(libs["real" if name == "mixed" else name])}
        trees[name] = fig
        cam = camera_for(items, SIZE, "front")
        text = f"{name}\n{fig['examples']} examples, {fig['lobes']} lobes\n{fig['leaves']:,} leaves"
        grown.append(labelled(render(items, SIZE, cam), text))
        structs.append(labelled(render(structure_items(hbl), SIZE, camera_for(structure_items(hbl), SIZE, "iso")),
                                f"{name}: assembled HBL"))
    save(side_by_side(grown), args.out / "freestyle_grown.png")
    save(side_by_side(structs), args.out / "freestyle_hbl.png")
    emit({"experiment": "freestyle", "seed": args.seed, "trees": trees,
          "libraries": {k: len(v) for k, v in libs.items()},
          "pictures": ["freestyle_grown.png", "freestyle_hbl.png"], "seconds": round(time.perf_counter() - t0, 2)})


if __name__ == "__main__":
    main()
