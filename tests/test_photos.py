"""``arboretum photos``: isolate/orient/scale on synthetic clouds, COLMAP model import, and (slow) SfM of
24 headless renders of a synthetic tree compared with its known shape."""

from __future__ import annotations

import json

import numpy as np
import pytest
from tests.photo_fixtures import (
    random_similarity,
    ring_cameras,
    tree_and_ground,
    write_colmap_model,
)

from arboretum_library.cli import main
from arboretum_library.errors import InputError
from arboretum_library.pointio import read_points
from arboretum_server.photos.align import chamfer, umeyama
from arboretum_server.photos.colmap_import import read_model
from arboretum_server.photos.isolate import (
    IsolateOptions,
    apply,
    isolate,
    main_cluster,
    rotation_to_z,
)

HEIGHT = 5.0


def _sfm_frame(seed: int):
    """A tree-on-ground cloud moved into an arbitrary similarity frame, with its camera ups."""
    rng = np.random.default_rng(seed)
    pts, kind = tree_and_ground(rng, HEIGHT)
    s, R, t = random_similarity(rng)
    up = np.tile(R @ [0.0, 0.0, 1.0], (12, 1)) + rng.normal(0, 0.1, (12, 3))
    return pts, kind, (s, R, t), s * pts @ R.T + t, up


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("with_cameras", [True, False])
def test_isolate_orients_cuts_and_scales(seed, with_cameras):
    pts, kind, _, moved, up = _sfm_frame(seed)
    iso = isolate(moved, IsolateOptions(height=0.8), up if with_cameras else None)
    assert iso.stats["ground_found"] and iso.stats["up_source"] == "ground"
    kept = kind[iso.index]
    assert (kept == 1).all()  # no ground point, no outlier
    assert (kept == 1).sum() >= 0.97 * (kind == 1).sum()  # the tree is all there
    assert iso.points[:, 2].max() == pytest.approx(0.8, rel=1e-9) and iso.points[:, 2].min() > 0
    # Z up again: the output height is the true height, scaled, for every kept point
    np.testing.assert_allclose(iso.points[:, 2], pts[iso.index, 2] * 0.8 / HEIGHT, atol=0.004)
    np.testing.assert_allclose(apply(iso.T_out_in, moved[iso.index]), iso.points, atol=1e-9)
    trunk = pts[iso.index, 2] < 0.5 * HEIGHT
    assert np.abs(iso.points[trunk, :2].mean(axis=0)).max() < 0.15 * 0.8 / HEIGHT  # origin within the trunk


def test_isolate_without_ground_uses_the_cameras():
    pts, kind, (s, R, t), _, up = _sfm_frame(3)
    tree = pts[kind == 1]
    iso = isolate(s * tree @ R.T + t, IsolateOptions(), up)
    assert not iso.stats["ground_found"] and iso.stats["up_source"] == "cameras"
    Rz = iso.T_out_in[:3, :3] / np.linalg.norm(iso.T_out_in[:3, 0])
    assert (Rz @ R @ [0.0, 0.0, 1.0])[2] > np.cos(np.radians(8))  # up within the cameras' noise


def test_isolate_rejects_too_few_points():
    with pytest.raises(InputError, match="points"):
        isolate(np.zeros((5, 3)))
    with pytest.raises(InputError, match="height"):
        IsolateOptions(height=0.0)


def test_rotation_to_z_and_main_cluster(rng):
    for v in [rng.normal(size=3), [0.0, 0.0, -1.0], [0.0, 0.0, 1.0]]:
        u = np.asarray(v) / np.linalg.norm(v)
        Rz = rotation_to_z(u)
        np.testing.assert_allclose(Rz @ u, [0, 0, 1], atol=1e-12)
        np.testing.assert_allclose(Rz @ Rz.T, np.eye(3), atol=1e-12)
    blob = rng.normal(size=(300, 3)) * 0.1
    stray = rng.normal(size=(30, 3)) * 0.1 + [5.0, 0, 0]
    idx, n = main_cluster(np.concatenate([blob, stray]), 4.0)
    assert n == 2 and sorted(idx) == list(range(300))


def test_umeyama_recovers_a_similarity(rng):
    src = rng.normal(size=(20, 3))
    s, R, t = random_similarity(rng)
    sim = umeyama(src, s * src @ R.T + t)
    assert sim.scale == pytest.approx(s, rel=1e-10)
    np.testing.assert_allclose(sim.R, R, atol=1e-10)
    np.testing.assert_allclose(sim.t, t, atol=1e-9)
    a, b = chamfer(src, src + [0.1, 0, 0])
    assert a == pytest.approx(0.1) and b == pytest.approx(0.1)


@pytest.mark.parametrize("binary", [False, True])
def test_colmap_model_import(tmp_path, binary):
    pytest.importorskip("pycolmap")
    rng = np.random.default_rng(4)
    pts, _ = tree_and_ground(rng, HEIGHT)
    eyes = ring_cameras(np.array([0.0, 0.0, 2.5]), 9.0, (2.0, 5.0), 8)
    model = tmp_path / "sparse" / "0"
    write_colmap_model(model, pts, eyes, np.array([0.0, 0.0, 2.5]), binary=binary)
    for folder in (model, tmp_path / "sparse"):  # the model, or its parent with numbered sub-models
        c = read_model(folder)
        assert c.stats["registered"] == 8 and len(c.points) == len(pts)
        np.testing.assert_allclose(c.camera_centres, eyes, atol=1e-9)
        assert (c.camera_up[:, 2] > 0.8).all()  # upright cameras, a little tilted down at the tree
        np.testing.assert_allclose(np.sort(c.points[:, 2]), np.sort(pts[:, 2]), atol=1e-9)


def test_colmap_import_errors(tmp_path):
    pytest.importorskip("pycolmap")
    with pytest.raises(InputError, match="not found"):
        read_model(tmp_path / "nope")
    with pytest.raises(InputError, match="no COLMAP model"):
        read_model(tmp_path)
    bad = tmp_path / "bad"
    bad.mkdir()
    for n in ("cameras", "images", "points3D"):
        (bad / f"{n}.bin").write_bytes(b"\x01\x02")
    with pytest.raises(InputError, match="cannot read"):
        read_model(bad)


def test_photos_cli_imports_a_model_in_any_frame(tmp_path, capsys):
    pytest.importorskip("pycolmap")
    rng = np.random.default_rng(5)
    pts, kind = tree_and_ground(rng, HEIGHT)
    eyes = ring_cameras(np.array([0.0, 0.0, 2.5]), 9.0, (2.0, 5.0), 12)
    sim = random_similarity(rng)
    write_colmap_model(tmp_path / "model", pts, eyes, np.array([0.0, 0.0, 2.5]), binary=True, sim=sim)
    out = tmp_path / "scan.ply"
    code = main(["photos", "--colmap-model", str(tmp_path / "model"), "--out", str(out), "--height", "2",
                 "--json"])
    assert code == 0
    data = json.loads(capsys.readouterr().out)
    cloud = read_points(out)
    n_tree = (kind == 1).sum()
    assert data["points"] == len(cloud) and 0.97 * n_tree <= len(cloud) <= n_tree  # ground and outliers gone
    assert cloud.points[:, 2].max() == pytest.approx(2.0, abs=1e-6)
    assert cloud.colors is not None and np.allclose(cloud.colors[0], [120 / 255, 90 / 255, 60 / 255], atol=0.01)
    # the true tree, scaled from 5 m to 2 m, stands where the output does (up to a turn about Z)
    q = [10, 50, 90]
    np.testing.assert_allclose(np.percentile(cloud.points[:, 2], q),
                               np.percentile(pts[kind == 1, 2] * 2.0 / HEIGHT, q), atol=0.02)


def test_photos_cli_errors(tmp_path, capsys):
    assert main(["photos", "--out", str(tmp_path / "x.ply")]) == 2
    assert "either IMAGES_DIR or --colmap-model" in capsys.readouterr().err
    (tmp_path / "imgs").mkdir()
    (tmp_path / "imgs" / "a.png").write_bytes(b"")
    assert main(["photos", str(tmp_path / "imgs"), "--out", str(tmp_path / "x.ply")]) == 2
    assert "found 1 image" in capsys.readouterr().err


@pytest.mark.slow
def test_photos_of_a_synthetic_tree_reconstruct_close_to_it(tmp_path, capsys):
    """24 views at 1024x768 -> SfM -> isolate: within 5 cm (1 % of the 5.4 m tree) of the truth."""
    pytest.importorskip("pycolmap")
    from tests.photo_fixtures import render_photos

    from arboretum_server.decompose.examples import counter_ids, make_examples, provenance
    from arboretum_server.decompose.options import DecomposeOptions
    from arboretum_server.decompose.pipeline import decompose
    from arboretum_server.synth.harmonic import grow_species

    photos = render_photos(grow_species("apple", 1), tmp_path / "images", views=24, size=(1024, 768))
    out = tmp_path / "scan.ply"
    assert main(["photos", str(photos.folder), "--out", str(out), "--work", str(tmp_path / "work"),
                 "--max-features", "16384", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["sfm"]["registered"] >= 22
    assert data["sfm"]["focal_px"] == pytest.approx(photos.focal_px, rel=0.01)
    idx = [photos.names.index(n) for n in data["image_names"]]
    sim = umeyama(np.asarray(data["camera_centres_out"]), photos.centres[idx])
    rms = np.sqrt(((sim.apply(np.asarray(data["camera_centres_out"])) - photos.centres[idx]) ** 2).sum(1).mean())
    assert rms < 0.03  # metres, on a ring of 6.2 m radius
    assert (sim.R @ [0.0, 0.0, 1.0])[2] > np.cos(np.radians(1.0))  # the output is Z up
    cloud = read_points(out)
    assert len(cloud) >= 60
    to_truth, _ = chamfer(sim.apply(cloud.points), photos.surface)
    # it failed in 2 of 13 whole slow-suite runs (1.06 and 1.13 m) before seeding; say what was kept
    assert to_truth < 0.05, (to_truth, cloud.up_axis, data["sfm"]["points"], data["isolate"])
    dec = decompose(cloud.points, DecomposeOptions(points=0, min_points=50, n_main=3, n_lobes=8))
    examples = make_examples(dec.hbl, provenance(out, DecomposeOptions()), counter_ids("photo"))
    assert len(examples) >= 2
