"""The service warms refinement's compiled loops when it starts (session 15's review: with numba's cache
cold, the first refinement edit waited about 5 s for compilation on the server's loop thread)."""

from __future__ import annotations


def test_warm_up_runs_each_heavy_modules_warm(monkeypatch):
    from arboretum_server.decompose import merge, similarity, tetloops
    from arboretum_server.service.dispatch import warm_up

    called = []
    for mod in (tetloops, merge, similarity):
        monkeypatch.setattr(mod, "warm", lambda name=mod.__name__: called.append(name))
    warm_up(("refine",))
    assert sorted(called) == sorted(m.__name__ for m in (tetloops, merge, similarity))


def test_warm_compiles_the_dtypes_the_alpha_shapes_use():
    from arboretum_server.decompose import merge, similarity, tetloops

    tetloops.warm()
    merge.warm()
    similarity.warm()
    sigs = [str(s) for s in tetloops._boundary_kernel.signatures]
    assert any(s.startswith("(Array(int32, 2") for s in sigs), sigs  # scipy's simplices are int32
    for kernel in (tetloops._circumspheres_kernel, tetloops._held_kernel, tetloops._closed_kernel,
                   merge._resample_kernel, similarity._chi_square_kernel):
        assert len(kernel.signatures) >= 1, kernel
