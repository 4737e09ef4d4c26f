"""Records survive flatten/unflatten and save_record/load_record bit for bit."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from arboretum_library.assembly import Assembly, LobeTransform, MergeLink, Placement
from arboretum_library.codec import (
    arrays_to_npz,
    flatten,
    load_record,
    npz_to_arrays,
    record_kind,
    save_record,
    unflatten,
)
from arboretum_library.descriptors import describe, tags_for
from arboretum_library.errors import InputError, ValidationError
from arboretum_library.geometry import make_transform
from arboretum_library.model import HBL, Branch, Example, Level, Lobe, Provenance


def sample_example(rng: np.random.Generator) -> Example:
    z = np.linspace(0, 1, 9)
    main = Branch(np.c_[0.1 * np.sin(3 * z), rng.normal(0, 0.01, 9), z], np.linspace(0.04, 0.01, 9))
    sec = Branch([[0, 0, 0.5], [0.2, 0.1, 0.6], [0.3, 0.1, 0.75]], [0.01, 0.008, 0.005], 0, 4, Level.SECONDARY)
    verts = rng.normal(size=(6, 3)) * 0.05 + [0.3, 0.1, 0.75]
    lobe = Lobe(rng.normal(size=(20, 3)) * 0.03 + [0.3, 0.1, 0.75], verts, [[0, 1, 2], [0, 2, 3], [0, 3, 4], [1, 2, 5]], [0.3, 0.1, 0.75], 1)
    h = HBL([0, 0, 0], [main, sec], [lobe], rng.normal(size=(30, 3)), rng.integers(0, 2, 30))
    d = describe(h)
    return Example("ex-7", h, Provenance("scan.xyz", "ab" * 32, "walnut", {"N_m": 10, "alpha": 13.0}), d, tags_for(d))


def assert_same(a, b, path="record"):
    if dataclasses.is_dataclass(a):
        assert type(a) is type(b), path
        for f in dataclasses.fields(a):
            assert_same(getattr(a, f.name), getattr(b, f.name), f"{path}.{f.name}")
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and np.array_equal(a, b), path
    elif isinstance(a, tuple):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            assert_same(x, y, f"{path}[{i}]")
    else:
        assert a == b and type(a) is type(b), path


def test_example_round_trip(rng):
    ex = sample_example(rng)
    meta, arrays = flatten(ex)
    back = unflatten(Example, meta, npz_to_arrays(arrays_to_npz(arrays)))
    assert_same(ex, back)
    assert back.structure.branches[1].level is Level.SECONDARY


def test_assembly_round_trip_through_a_file(tmp_path, rng):
    ex = sample_example(rng)
    p = Placement("a", ex.id, make_transform(t=[1, 0, 0]), 2.0, (LobeTransform(0, make_transform(scale=1.2)),))
    asm = Assembly((p, Placement("b", "sk", np.eye(4))), (dataclasses.replace(ex, id="sk"),), (MergeLink("a", "b", 3, 2),))
    path = save_record(tmp_path / "s.npz", asm)
    assert record_kind(path) == "Assembly"
    assert_same(asm, load_record(path, Assembly))
    assert not list(tmp_path.glob(".*tmp"))


def test_unflatten_reports_missing_and_bad_values(rng):
    meta, arrays = flatten(sample_example(rng))
    del arrays["structure/branches/1/radii"]
    with pytest.raises(ValidationError, match="structure/branches/1/radii"):
        unflatten(Example, meta, arrays)
    meta2, arrays2 = flatten(sample_example(rng))
    meta2["descriptors"]["lobe_count"] = "many"
    with pytest.raises(ValidationError, match="lobe_count"):
        unflatten(Example, meta2, arrays2)


def test_load_record_errors_name_the_file(tmp_path, rng):
    path = save_record(tmp_path / "e.npz", sample_example(rng))
    with pytest.raises(InputError, match="expected HBL"):
        load_record(path, HBL)
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(InputError, match="bad.npz"):
        load_record(bad, HBL)
    plain = tmp_path / "plain.npz"
    np.savez(plain, x=np.zeros(3))
    with pytest.raises(InputError, match="not an Arboretum record"):
        load_record(plain, HBL)
    with pytest.raises(InputError, match="no such file"):
        load_record(tmp_path / "none.npz", HBL)


def test_npz_refuses_pickled_objects(tmp_path):
    path = tmp_path / "obj.npz"
    np.savez(path, x=np.array([{"a": 1}], dtype=object))
    with pytest.raises(ValidationError, match="not a readable"):
        npz_to_arrays(path.read_bytes())
