"""Module sets read once per process, and the skeleton's isolines grouped in one pass (session 26).

A server answering ``modules`` requests read the bundled set and extracted its 25 skeletons on every request
(0.75-1.1 s CPU); ``load_module_set`` now keeps what it read while the files are unchanged, read-only, and
``skeleton._isoline_islands`` finds the islands of every level with one connected-components call."""

from __future__ import annotations

import os

import numpy as np
import pytest
from scipy.sparse.csgraph import dijkstra

from arboretum_server.modules import skeleton as sk
from arboretum_server.modules.moduleset import load_module_set, save_module_set
from arboretum_server.modules.procedural import make_default_module_set


@pytest.fixture(scope="module")
def two_modules(tmp_path_factory):
    folder = tmp_path_factory.mktemp("mods")
    ms = make_default_module_set(np.random.default_rng(7)).subset(["trunk_00_straight", "branch_02_fork"])
    save_module_set(ms, folder)
    return folder


def test_a_folder_is_read_once_while_its_files_are_unchanged(two_modules):
    first = load_module_set(two_modules)
    again = load_module_set(two_modules)
    assert again is first
    assert load_module_set(two_modules, up="z") is not first  # another reading of headerless files


def test_a_rewritten_file_is_read_again(tmp_path, two_modules):
    for p in two_modules.iterdir():
        (tmp_path / p.name).write_bytes(p.read_bytes())
    first = load_module_set(tmp_path)
    fork = tmp_path / "branch_02_fork.obj"
    text = fork.read_text().splitlines()
    # every vertex twice as far from the base: the module's size doubles
    scaled = [" ".join(["v"] + [f"{2 * float(x):.6f}" for x in ln.split()[1:4]]) if ln.startswith("v ") else ln
              for ln in text]
    fork.write_text("\n".join(scaled) + "\n")
    st = fork.stat()
    os.utime(fork, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))
    second = load_module_set(tmp_path)
    assert second is not first
    size = {m.name: m.size for m in first.modules}["branch_02_fork"]
    assert {m.name: m.size for m in second.modules}["branch_02_fork"] == pytest.approx(2 * size, rel=1e-3)


def test_a_kept_set_cannot_be_changed_in_place(two_modules):
    m = load_module_set(two_modules).modules[0]
    for a in (m.vertices, m.faces, m.skeleton.points, m.skeleton.radius, m.skeleton.tips):
        with pytest.raises(ValueError, match="read-only"):
            a[0] = a[0]


def test_islands_of_all_levels_at_once_equal_one_level_at_a_time(two_modules):
    """The fork module's isolines: one island below the fork, two above; the same lengths and mids
    whether the levels are grouped in one graph or read one by one."""
    fork = next(m for m in load_module_set(two_modules).modules if m.name == "branch_02_fork")
    v, f = np.asarray(fork.vertices, float), np.asarray(fork.faces, np.int64)
    low = np.flatnonzero(v[:, 2] <= v[:, 2].min() + 1e-3 * np.ptp(v, axis=0).max())
    g = dijkstra(sk._edge_graph(v, f), directed=False, indices=low, min_only=True)
    g[low] = 0.0
    levels = g.max() * np.arange(1, 32) / 32
    together = sk._isoline_islands(v, f, g, levels)
    alone = [sk._isoline_islands(v, f, g, [lv])[0] for lv in levels]
    counts = [len(x) for x in together]
    assert counts == [len(x) for x in alone]
    assert counts[0] == 1 and max(counts) >= 2
    for a, b in zip(together, alone):
        for (wa, ma), (wb, mb) in zip(a, b):
            assert np.array_equal(wa, wb) and np.array_equal(ma, mb)
