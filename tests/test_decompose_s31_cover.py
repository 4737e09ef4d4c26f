"""Leaf cover through the virtual scanner (session 31): the main branches' clearance at their tips, and the
twigs among given leaf labels.

Session 30 found 3 of 144 virtual-scanner runs (seeds 1-4) covering under 95 % of their leaf points within
1 cm of a lobe hull. The harmonic walnut, seed 3, leaf-on (0.938): the leaves round its main branches' tips
were taken for main-branch wood, 1.7 cm round a tip 1.6 mm thick, because the clearance was read from the
spacing of the sparse leaves there. The guiding-vector elm, seed 3, with given labels (0.944): only the
labelled leaves were clustered, and the scan's leaves beside the twigs, lost in the downsampling to 12,000
points, lay outside every hull.
"""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_library.model import LEAF, WOOD
from arboretum_server.decompose.options import DecomposeOptions
from arboretum_server.decompose.pipeline import CROWN_BASE, foliage_points
from arboretum_server.decompose.radii import path_radii
from arboretum_server.decompose.report import synth_figures


def test_path_radii_share_the_trunk_among_the_tips():
    # three paths from the root: the trunk (segment 0, vertices 0-2) carries all three, segment 1 forks at
    # trunk vertex 2 and carries two (its own tip and segment 2's, which leaves it at its vertex 1)
    owner = [np.array([[0, 0], [0, 1], [0, 2]]),
             np.array([[0, 0], [0, 1], [0, 2], [1, 1], [1, 2]]),
             np.array([[0, 0], [0, 1], [0, 2], [1, 1], [2, 1], [2, 2]])]
    r = path_radii(owner, 0.03)
    assert [len(x) for x in r] == [3, 5, 6]
    np.testing.assert_allclose(r[0], [0.03] * 3)
    np.testing.assert_allclose(r[1][3:], [0.03 * np.sqrt(2 / 3), 0.03 * np.sqrt(1 / 3)])
    np.testing.assert_allclose(r[2][3:], [0.03 * np.sqrt(2 / 3), 0.03 * np.sqrt(1 / 3), 0.03 * np.sqrt(1 / 3)])
    assert path_radii([], 0.03) == []


def test_given_labels_cluster_the_twigs_off_the_main_branches_but_not_the_bare_trunk():
    # 200 leaves, 100 twig points off the main branches in the crown, 50 on a main branch, 50 on the bare
    # trunk (off the main branch's wood by the clearance, below the crown base by the bare-trunk rule; the
    # caller relabels them wood when the labels were guessed)
    n = 400
    pts = np.zeros((n, 3))
    pts[:, 2] = 0.5
    labels = np.full(n, WOOD, np.uint8)
    labels[:200] = LEAF
    off_main = np.ones(n, bool)
    off_main[300:350] = False
    bare = np.zeros(n, bool)
    bare[350:] = True
    fol, source = foliage_points(labels, pts, off_main, DecomposeOptions(n_lobes=10), bare)
    assert source == "leaf"
    np.testing.assert_array_equal(fol, np.arange(300))
    # a given leaf on the bare trunk (a shoot from the trunk) stays a leaf of the foliage
    labels[390:] = LEAF
    fol, _ = foliage_points(labels, pts, off_main, DecomposeOptions(n_lobes=10), bare)
    np.testing.assert_array_equal(fol, np.r_[np.arange(300), np.arange(390, 400)])
    labels[390:] = WOOD
    # the lowest 5 % of the tree never joins, whatever its label says
    pts[250:300, 2] = CROWN_BASE / 2
    fol, _ = foliage_points(labels, pts, off_main, DecomposeOptions(n_lobes=10), bare)
    np.testing.assert_array_equal(fol, np.arange(250))


@pytest.mark.parametrize(("model", "species", "case", "before"), [
    ("harmonic", "walnut", "leaf-on", 0.9378),
    ("guiding", "elm", "leaf-on+labels", 0.9442),
])
def test_scanner_runs_that_covered_under_95_percent_now_hold_the_floor(model, species, case, before):
    f = synth_figures(species, 3, case, scanner=True, model=model)
    # session 31: 0.9675 and 0.9798 (``before`` on session 30's code); the lowest of the 144 runs 0.959
    assert f["leaf_cover"] >= 0.95 > before
    assert f["counts_ok"] and f["connected"] and f["crossings"] == 0
