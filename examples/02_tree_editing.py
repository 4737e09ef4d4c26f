"""Tree editing (VRTree 4.2, Fig. 8): load a decomposed real tree whole, then augment it and replace a part.

The real scan 07 is decomposed into examples (one per main branch). Loading it whole places every
example at its original pose (identity transforms, recombination off: loading must not join again
what the decomposition joined), and ``assembly_to_hbl`` must give back the decomposition's HBL: every branch and lobe bit-identical.
Then the tree is edited: one example is removed and an example of another tree (a harmonic walnut)
put in its place (turned to the removed branch's direction and scaled to its length), and two more
walnut examples are added on the trunk in the widest empty direction (augmentation). Each new example
is joined by Algorithm 1 to the placed main branch it is most similar to among those it touches (the
recombination rule, applied to the new example only). The untouched examples' branches must be
bit-identical in the edited HBL.

    python examples/02_tree_editing.py --out out/editing --seed 0
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
from _common import (
    about_base,
    attach,
    azimuth,
    branch_key,
    camera_for,
    emit,
    grown_items,
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

SIZE = (360, 420)
NEW_RGBA = (0.10, 0.35, 0.95, 1.0)


def load_whole(examples: list, get):
    """Every example at its original pose (identity), recombination off."""
    from arboretum_library.assembly import Assembly
    from arboretum_server.assembly import ops
    from arboretum_server.assembly.recombine import RecombineOptions

    a = Assembly()
    for ex in examples:
        a, _ = ops.add_example(a, get, ex.id, np.eye(4), 1.0, ex.id, RecombineOptions(enabled=False))
    return a


def hbl_keys(hbl) -> tuple[list[bytes], list[bytes]]:
    """Exact keys of every branch (vertices, radii) and lobe (points, hull vertices) of ``hbl``."""
    branches = [branch_key(b.points, b.radii) for b in hbl.branches]
    lobes = [branch_key(lb.points, lb.hull_vertices) for lb in hbl.lobes]
    return branches, lobes


def place_like(a, get, new, old, name: str):
    """Put example ``new`` where example ``old``'s main branch was: same base, direction and length."""
    from arboretum_server.assembly import ops
    from arboretum_server.assembly.recombine import RecombineOptions

    scale = length(old) / length(new)
    T = about_base(new, azimuth(old) - azimuth(new), scale, new.structure.branches[0].points[0])
    T[:3, 3] += old.structure.branches[0].points[0] - new.structure.branches[0].points[0]
    a, _ = ops.add_example(a, get, new.id, T, scale, name, RecombineOptions(enabled=False))
    return attach(a, get, name)


def length(example) -> float:
    """Length of the example's main branch, metres."""
    from arboretum_library.geometry import polyline_lengths

    return float(polyline_lengths(example.structure.branches[0].points)[-1])


def widest_gap(examples: list) -> float:
    """Degrees: the middle of the widest azimuth gap between the examples' main branches."""
    az = np.sort([azimuth(e) % 360 for e in examples[1:]])
    gaps = np.diff(np.r_[az, az[0] + 360])
    k = int(np.argmax(gaps))
    return float(az[k] + gaps[k] / 2)


def edit(whole, get, tree: list, donors: list):
    """Remove one example, put a donor in its place, add two donors on the trunk: (assembly, removed id)."""
    from arboretum_server.assembly import ops
    from arboretum_server.assembly.recombine import RecombineOptions

    heights = [e.structure.branches[0].points[0, 2] for e in tree[1:]]
    old = tree[1 + int(np.argsort(heights)[len(heights) // 2])]  # the main branch starting mid-height
    a, _ = ops.delete_example(whole, old.id)
    lengths = [len(d.structure.branches[0].points) for d in donors[1:]]
    want = len(old.structure.branches[0].points)
    a = place_like(a, get, donors[1 + int(np.argmin(np.abs(np.subtract(lengths, want))))], old, "replacement")
    trunk = tree[0].structure.branches[0].points
    gap = widest_gap([e for e in tree if e.id != old.id])
    lo, hi = min(heights), max(heights)
    for k, (frac, turn) in enumerate(((0.3, gap), (0.7, gap + 40.0))):
        donor = donors[1 + k]
        base = trunk[int(np.argmin(np.abs(trunk[:, 2] - (lo + frac * (hi - lo)))))]
        scale = length(old) / length(donor)
        T = about_base(donor, turn - azimuth(donor), scale, donor.structure.branches[0].points[0])
        T[:3, 3] += base - donor.structure.branches[0].points[0]
        a, _ = ops.add_example(a, get, donor.id, T, scale, f"added{k}", RecombineOptions(enabled=False))
        a = attach(a, get, f"added{k}")
    return a, old.id


def main() -> None:
    args = parse_args(__doc__)
    t0 = time.perf_counter()
    from arboretum_server.assembly.world import assembly_to_hbl, placed_structure

    dec, tree = library(*real_scan("07_itsme_buttressed_tree_1"), "walnut", "scan07", args.seed)
    pts, labels = synth_scan("walnut", args.seed + 11)
    donors = library(pts, labels, "walnut", "walnut", args.seed)[1]
    get = source(tree, donors)
    whole = load_whole(tree, get)
    whole_hbl = assembly_to_hbl(whole, get)
    ob, ol = hbl_keys(dec.hbl)
    wb, wl = hbl_keys(whole_hbl)
    edited, removed = edit(whole, get, tree, donors)
    edited_hbl = assembly_to_hbl(edited, get)
    eb, el = hbl_keys(edited_hbl)
    kept = [p for p in whole.placements if p.instance != removed]
    kb = [branch_key(b.points, b.radii) for p in kept for b in placed_structure(p, get(p.example_id)).branches]
    rb = [branch_key(b.points, b.radii) for b in get(removed).structure.branches]
    figures = {
        "examples": len(tree), "original_branches": len(ob), "original_lobes": len(ol),
        "whole_branches_identical": sum(k in set(ob) for k in wb), "whole_lobes_identical": sum(k in set(ol) for k in wl),
        "whole_equals_original": sorted(ob) == sorted(wb) and sorted(ol) == sorted(wl),
        "removed": removed, "removed_branches": len(rb), "removed_branches_left": sum(k in set(eb) for k in rb),
        "untouched_branches": len(kb), "untouched_branches_identical": sum(k in set(eb) for k in kb),
        "edited_placements": len(edited.placements), "edited_merges": len(edited.merges),
        "edited_branches": len(eb), "edited_lobes": len(el),
        "new_branches": sum(k not in set(kb) for k in eb),
    }
    pictures(args, dec.hbl, edited_hbl, set(kb))
    emit({"experiment": "tree_editing", "seed": args.seed, **figures, "pictures": ["editing.png"],
          "seconds": round(time.perf_counter() - t0, 2)})


def pictures(args, original, edited, kept: set) -> None:
    """Original HBL | its crown | edited crown (new branches blue) | edited tree grown."""
    nb = len(edited.branches)
    items = structure_items(edited)
    items = [replace(it, color=np.asarray(NEW_RGBA, np.float32)) if i < nb and branch_key(
        edited.branches[i].points, edited.branches[i].radii) not in kept else it for i, it in enumerate(items)]
    grown, _ = grown_items(edited, args.seed)
    from arboretum_client.camera import fit_camera

    crown = np.concatenate([lb.hull_vertices for lb in (*original.lobes, *edited.lobes)])
    close = fit_camera(np.stack([crown.min(axis=0), crown.max(axis=0)]), "iso", SIZE[0] / SIZE[1])
    panels = [labelled(render(structure_items(original), SIZE, camera_for(structure_items(original), SIZE, "iso")),
                       "scan 07 decomposed (original HBL)"),
              labelled(render(structure_items(original), SIZE, close), "its crown"),
              labelled(render(items, SIZE, close), "edited: 1 replaced, 2 added (blue)"),
              labelled(render(grown, SIZE, close), "edited tree grown")]
    save(side_by_side(panels), args.out / "editing.png")


if __name__ == "__main__":
    main()
