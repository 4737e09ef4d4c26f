"""The module exporter clusters its pieces without scikit-learn (session 31), as the lobes do since session 30."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

from arboretum_server.decompose.clusters import kmeans
from arboretum_server.modules import convert


def _inertia(sig: np.ndarray, labels: np.ndarray) -> float:
    return float(sum(((sig[labels == t] - sig[labels == t].mean(axis=0)) ** 2).sum() for t in np.unique(labels)))


def test_the_types_are_the_best_of_the_seeded_runs():
    # four well-apart blobs of 8-dimensional signatures, clustered into 6 types: the kept clustering has the
    # least inertia of the INITS runs drawn from the same generator, and the medoid lies in its own type
    rng = np.random.default_rng(5)
    sig = np.concatenate([rng.normal(c, 0.3, size=(60, 8)) for c in (0.0, 3.0, 6.0, 9.0)])
    labels, medoid = convert._cluster(sig, 6, np.random.default_rng(11))
    runs = np.random.default_rng(int(np.random.default_rng(11).integers(0, 2**31 - 1)))
    inertias = [_inertia(sig, kmeans(sig, 6, runs)[0]) for _ in range(convert.INITS)]
    assert len(set(np.round(inertias, 9))) > 1  # the runs differ: choosing among them matters here
    assert _inertia(sig, labels) == min(inertias)
    assert labels.shape == (240,) and sorted(set(labels.tolist())) == list(range(6))
    assert [int(labels[m]) for m in medoid] == list(range(6))
    _, first = np.unique(labels, return_index=True)
    assert list(labels[np.sort(first)]) == list(range(6))  # types numbered by first appearance


def test_fewer_distinct_signatures_than_types_give_that_many_types():
    sig = np.repeat(np.eye(3), 5, axis=0)
    labels, medoid = convert._cluster(sig, 8, np.random.default_rng(0))
    assert len(medoid) == 3 and sorted(set(labels.tolist())) == [0, 1, 2]


def test_a_conversion_imports_no_scikit_learn():
    code = (
        "import sys, numpy as np\n"
        "from arboretum_server.grow.demo import demo_hbl\n"
        "from arboretum_server.grow.options import GrowOptions\n"
        "from arboretum_server.grow.tree import grow_tree\n"
        "from arboretum_server.modules.convert import ConvertOptions, convert_tree\n"
        "t = grow_tree(demo_hbl(np.random.default_rng(0), n_lobes=4), GrowOptions(), np.random.default_rng(0))\n"
        "c = convert_tree(t, ConvertOptions(types=4), np.random.default_rng(0))\n"
        "print(len(set(c.module.tolist())), 'sklearn' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    # session 31: scikit-learn's import cost `arboretum modules` 0.9-1.3 s of its start
    assert out.stdout.split() == ["4", "False"], out.stderr
