"""A tree declared leaf-off (session 15): every point reported wood, the geometry as without the flag,
through the pipeline, ``arboretum decompose``, ``library build``, the service and the client's --scan."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from arboretum_library.assets import sample_scans
from arboretum_library.cli import main
from arboretum_library.errors import InputError
from arboretum_library.model import LEAF, WOOD
from arboretum_library.pointio import read_points
from arboretum_library.store import Library
from arboretum_server.decompose.examples import provenance, same_run
from arboretum_server.decompose.options import DecomposeOptions
from arboretum_server.decompose.pipeline import decompose
from factories import toy_cloud

COFFEE = sample_scans()[0]


@pytest.fixture(scope="module")
def pair():
    """The toy tree's leaf-on toy scan decomposed as guessed and declared leaf-off (its guessed leaves
    are the leaf-off case's 'fine wood': a leafless crown's twig tufts read the same)."""
    pts, _ = toy_cloud()
    o = DecomposeOptions(points=0, n_main=3, n_lobes=8)
    return decompose(pts, o), decompose(pts, replace(o, leaf_off=True))


def test_declared_leaf_off_reports_every_point_wood(pair):
    guessed, off = pair
    n_leaf = int((guessed.labels == LEAF).sum())
    assert n_leaf > 100  # the guess calls part of it leaf: the flag has something to change
    assert off.labels.dtype == np.uint8 and off.labels.shape == guessed.labels.shape
    assert not off.labels.any() and not off.hbl.labels.any() and (off.hbl.labels == WOOD).all()
    assert (off.stats["leaf_points"], off.stats["labels"], off.stats["fine_wood_points"]) == (0, "leaf-off", n_leaf)
    assert guessed.stats["leaf_points"] == n_leaf and "fine_wood_points" not in guessed.stats


def test_declared_leaf_off_keeps_the_geometry(pair):
    guessed, off = pair
    a, b = guessed.hbl, off.hbl
    assert len(a.branches) == len(b.branches) > 3 and len(a.lobes) == len(b.lobes) == 8
    for x, y in zip(a.branches, b.branches, strict=True):
        assert np.array_equal(x.points, y.points) and np.array_equal(x.radii, y.radii) and x.parent == y.parent
    for x, y in zip(a.lobes, b.lobes, strict=True):
        assert np.array_equal(x.hull_vertices, y.hull_vertices) and np.array_equal(x.hull_faces, y.hull_faces)
        assert np.array_equal(x.points, y.points) and x.branch == y.branch
    assert np.array_equal(guessed.lobe_of, off.lobe_of)


def test_leaf_off_must_be_true_or_false():
    with pytest.raises(InputError, match="decomposition option leaf_off: must be true or false, got 'yes'"):
        DecomposeOptions(leaf_off="yes")


def test_leaf_off_makes_the_same_examples_so_the_same_run():
    # examples carry no point labels: a leaf-off run of a stored scan stores nothing again (the review
    # found every example stored twice when leaf_off was part of the run's identity)
    old = provenance("a.xyz", DecomposeOptions(), sha256="0" * 64)
    older = replace(old, parameters={k: v for k, v in old.parameters.items() if k != "leaf_off"})
    off = provenance("a.xyz", DecomposeOptions(leaf_off=True), sha256="0" * 64)
    assert same_run(old, off) and same_run(older, off) and off.parameters["leaf_off"] is True
    assert not same_run(old, provenance("a.xyz", DecomposeOptions(seed=1), sha256="0" * 64))


def test_a_leaf_off_run_of_a_stored_scan_stores_nothing_again(tmp_path, capsys):
    lib = tmp_path / "L"
    assert main(["decompose", str(COFFEE), "--library", str(lib), "--points", "2000", "--json"]) == 0
    first = json.loads(capsys.readouterr().out)["stored"]
    assert main(["decompose", str(COFFEE), "--library", str(lib), "--points", "2000", "--leaf-off", "--json"]) == 0
    again = json.loads(capsys.readouterr().out)
    assert len(first) == 8 and again["stored"] == [] and again["already"] == first


def test_all_fine_wood_gets_the_all_foliage_note_in_its_own_words():
    from arboretum_server.decompose.notes import scan_notes

    guessed = scan_notes({"points": 12000, "leaf_points": 11700, "labels": "guessed"})
    off = scan_notes({"points": 12000, "leaf_points": 0, "fine_wood_points": 11700, "labels": "leaf-off"})
    assert guessed[0].startswith("97.5% of the points are foliage (guessed labels)")
    assert off == ["97.5% of the points read as fine, space-filling wood and almost none as stems: the branches "
                   "were routed through it and are a guess (is this one tree, with its trunk?)"]
    assert scan_notes({"points": 12000, "leaf_points": 0, "fine_wood_points": 300, "labels": "leaf-off"}) == []


def test_the_command_says_leaf_off_and_saves_an_all_wood_hbl(tmp_path, capsys):
    out = tmp_path / "tree.npz"
    assert main(["decompose", str(COFFEE), "--leaf-off", "--save-hbl", str(out), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["stats"]["leaf_points"] == 0 and data["stats"]["labels"] == "leaf-off"
    assert data["options"]["leaf_off"] is True and data["stats"]["fine_wood_points"] > 0
    assert main(["decompose", str(COFFEE), "--leaf-off"]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert first.endswith(f"12000 used, 0 leaf (declared leaf-off; {data['stats']['fine_wood_points']} points "
                          "of fine wood), 0 ground removed")
    from arboretum_library.codec import load_record
    from arboretum_library.model import HBL

    hbl = load_record(out, HBL)
    assert len(hbl.labels) == 12000 and not hbl.labels.any()


def test_library_build_declares_every_scan_leaf_off(tmp_path):
    from arboretum_server.batch.build import BuildOptions, build_library

    lib = tmp_path / "lib"
    scans = [str(COFFEE)]
    first = build_library(scans, lib, BuildOptions(workers=1, points=1500))
    assert first.count("added") == 1 and first.records[0].stats["labels"] == "guessed"
    again = build_library(scans, lib, BuildOptions(workers=1, points=1500, leaf_off=True))
    assert again.count("skipped") == 1 and again.records[0].notes == []  # the same examples: nothing to say
    redone = build_library(scans, lib, BuildOptions(workers=1, points=1500, leaf_off=True, rebuild=True))
    rec = redone.records[0]
    assert rec.status == "added" and rec.stats["leaf_points"] == 0 and rec.stats["labels"] == "leaf-off"
    with Library.open(lib, readonly=True) as L:
        assert {L.provenance(i).parameters["leaf_off"] for i in rec.examples} == {True}
        assert len(L) == len(rec.examples) == len(first.records[0].examples)


def test_the_service_opens_a_leaf_off_draft_all_wood(tmp_path):
    from arboretum_library import protocol as P
    from factories import dispatcher, reply_of, service_folders

    pts, labels = toy_cloud()
    with dispatcher(*service_folders(tmp_path)) as d:
        sid = reply_of(d, P.SessionNew()).session
        opts = {"n_main": 3, "n_lobes": 8, "points": 0}
        guessed = reply_of(d, P.RefineOpen(session=sid, points=pts, labels=None, name="g", options=opts))
        cloud = reply_of(d, P.RefineOpen(session=sid, points=pts, labels=labels, name="off",
                                         options=opts | {"leaf_off": True}))
    assert guessed.hbl.labels.any() and cloud.hbl.labels.shape == (len(pts),) and not cloud.hbl.labels.any()


def test_the_client_passes_leaf_off_with_its_scan_and_refuses_it_alone(tmp_path):
    import argparse

    from arboretum_client.app_cli import _scan, check_args

    scan = _scan(str(COFFEE), leaf_off=True)
    assert scan.options == {"leaf_off": True} and len(scan.points) == len(read_points(COFFEE).points)
    assert _scan(str(COFFEE)).options == {}
    args = argparse.Namespace(size="64x64", headless=False, script=None, main=None, lobes=None,
                              species="unknown", up="auto", leaf_off=True, scan=None, connect=None)
    with pytest.raises(InputError, match=r"--leaf-off apply to the --scan file, and no --scan was given"):
        check_args(args)
