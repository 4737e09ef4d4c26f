"""The server's export.modules job takes the CLI's path: same module set, trunk, scale and file."""

from __future__ import annotations

import dataclasses

import numpy as np
import pygltflib
import pytest

from arboretum_library.cli import main
from arboretum_library.codec import save_record
from arboretum_library.errors import InputError
from arboretum_library.model import HBL
from arboretum_server.grow.demo import demo_hbl
from arboretum_server.service.handlers.modules import export_modules_job


def _meshes(data: bytes, tmp_path, name: str) -> dict[str, np.ndarray]:
    """Module name -> (V, 3) float32 vertices of every mesh in a GLB."""
    path = tmp_path / name
    path.write_bytes(data)
    g = pygltflib.GLTF2().load(str(path))
    blob = g.binary_blob()
    out = {}
    for m in g.meshes:
        a = g.accessors[m.primitives[0].attributes.POSITION]
        v = g.bufferViews[a.bufferView]
        out[m.name] = np.frombuffer(blob, np.float32, 3 * a.count, v.byteOffset + (a.byteOffset or 0))
    return out


@pytest.fixture(scope="module")
def hbl():
    return demo_hbl(np.random.default_rng(0), n_lobes=8)


def test_server_job_writes_the_same_file_as_the_cli(tmp_path, hbl):
    save_record(tmp_path / "hbl.npz", hbl)
    out = tmp_path / "cli.glb"
    assert main(["modules", "--assembly", str(tmp_path / "hbl.npz"), "--out", str(out), "--seed", "3"]) == 0
    job = export_modules_job(lambda *a: None, hbl, 3, {}, "glb-instanced")
    assert job["data"].tobytes() == out.read_bytes()
    assert job["stats"]["instances"] >= 2 and 0 < job["stats"]["module_scale"]
    # the module shapes come from assets/modules/default, not from the request's seed
    other = export_modules_job(lambda *a: None, hbl, 4, {}, "glb-instanced")
    a, b = _meshes(job["data"].tobytes(), tmp_path, "a.glb"), _meshes(other["data"].tobytes(), tmp_path, "b.glb")
    shared = sorted(set(a) & set(b))
    assert len(shared) >= 2 and all(np.array_equal(a[n], b[n]) for n in shared)


def test_server_job_refuses_an_hbl_without_branches(hbl):
    lobes = tuple(dataclasses.replace(lb, branch=-1) for lb in hbl.lobes[:2])
    with pytest.raises(InputError, match="has no branches"):
        export_modules_job(lambda *a: None, HBL(root=hbl.root, branches=(), lobes=lobes), 0, {})
