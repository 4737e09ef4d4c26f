"""``arrays_to_npz`` writes exactly the bytes ``np.savez`` writes (their SHA-256 identifies an example),
directly, without ``zipfile``; and falls back to ``np.savez`` whenever the direct writer would differ."""

from __future__ import annotations

import io
import warnings
import zipfile

import numpy as np
import pytest

from arboretum_library import codec, npzwrite
from arboretum_library.codec import arrays_to_npz, flatten, npz_to_arrays

DTYPES = (np.float64, np.float32, np.int32, np.int64, np.uint8, np.bool_)


def savez_bytes(arrays) -> bytes:
    """What numpy writes (the reference: the code before the direct writer)."""
    buf = io.BytesIO()
    np.savez(buf, **{k: np.ascontiguousarray(a) for k, a in arrays.items()})
    return buf.getvalue()


def assert_as_numpy(arrays) -> None:
    """The direct writer handles ``arrays`` (no fallback), its bytes are numpy's, and they read back equal."""
    contiguous = {k: np.ascontiguousarray(a) for k, a in arrays.items()}
    direct = npzwrite.npz_bytes(contiguous)
    assert direct is not None, "the direct writer declined: this test would only test np.savez"
    expected = savez_bytes(arrays)
    assert direct == expected
    assert arrays_to_npz(arrays) == expected
    back = npz_to_arrays(direct)
    assert list(back) == list(arrays)
    with np.load(io.BytesIO(direct), allow_pickle=False) as z:
        assert z.files == list(arrays)
        for k, a in arrays.items():
            want = np.ascontiguousarray(a)
            for got in (back[k], z[k]):
                assert got.dtype == want.dtype and got.shape == want.shape and got.tobytes() == want.tobytes()


def random_array(rng: np.random.Generator, dtype) -> np.ndarray:
    shape = tuple(int(n) for n in rng.integers(0, 6, size=rng.integers(0, 4)))
    return (rng.normal(size=shape) * 100).astype(dtype)


@pytest.mark.parametrize("dtype", DTYPES)
def test_each_model_dtype_in_every_shape_kind_is_written_as_numpy_writes(dtype):
    a = np.arange(60).astype(dtype)
    assert_as_numpy({
        "scalar": np.array(3, dtype=dtype),
        "empty": np.zeros(0, dtype=dtype),
        "none_of_three": np.zeros((0, 3), dtype=dtype),
        "three_of_none": np.zeros((3, 0), dtype=dtype),
        "points": a.reshape(20, 3),
        "cube": a.reshape(3, 4, 5),
        "fortran": np.asfortranarray(a.reshape(6, 10)),
        "strided": a.reshape(20, 3)[::2, ::-1],
        "transposed": a.reshape(4, 15).T,
        "large": np.resize(a, 70_000 // np.dtype(dtype).itemsize + 13),
    })


def test_byte_orders_long_first_axes_and_other_plain_dtypes_are_written_as_numpy_writes():
    assert_as_numpy({
        "big_endian": np.arange(7, dtype=">f8"),
        "big_int": np.arange(7, dtype=">i4").reshape(7, 1),
        "complex": np.arange(4) * (1 + 2j),
        "half": np.arange(5, dtype=np.float16),
        "uint16": np.arange(5, dtype=np.uint16),
        "bytes": np.array([b"ab", b"c"]),
        "text": np.array(["tree", "é"]),
        "day": np.arange(3).astype("datetime64[D]"),
        "long_axis": np.zeros((10**7, 0), dtype=np.int32),  # a 8-digit first axis: less growth padding
        "many_dims": np.zeros((1,) * 32),
    })


@pytest.mark.parametrize("n", [0, 1, 2, 200])
def test_any_number_of_arrays_is_written_as_numpy_writes(n):
    rng = np.random.default_rng(n)
    assert_as_numpy({f"a{i}/v": random_array(rng, DTYPES[i % len(DTYPES)]) for i in range(n)})


@pytest.mark.parametrize("length", [1, 2, 7, 59, 60, 61, 120, 255, 1000])
def test_member_names_of_any_length_are_written_as_numpy_writes(length):
    name = ("structure/lobes/" * 100)[:length]
    assert_as_numpy({name: np.arange(3.0), "x" * length: np.ones((2, 2), dtype=np.float32)})


def test_a_utf8_member_name_gets_zipfiles_utf8_flag():
    assert_as_numpy({"été/points": np.arange(3.0)})


def test_fifty_random_array_sets_are_written_as_numpy_writes():
    rng = np.random.default_rng(7)
    for _ in range(50):
        n = int(rng.integers(1, 12))
        assert_as_numpy({f"k{i}": random_array(rng, DTYPES[int(rng.integers(len(DTYPES)))]) for i in range(n)})


def test_library_examples_are_written_as_numpy_writes():
    from factories import make_example

    rng = np.random.default_rng(3)
    for i in range(5):
        assert_as_numpy(flatten(make_example(rng, n_lobes=i + 1, curved=bool(i % 2)))[1])


@pytest.fixture(scope="module")
def decomposed_examples():
    from arboretum_server.decompose.examples import counter_ids, make_examples, provenance
    from arboretum_server.decompose.options import DecomposeOptions
    from arboretum_server.decompose.pipeline import decompose
    from arboretum_server.decompose.toytree import toy_scan, toy_truth

    old = np.seterr(all="raise", under="ignore")  # the module fixture runs outside conftest's autouse one
    try:
        pts, _ = toy_scan(toy_truth(), n=8000, seed=1)
        options = DecomposeOptions()
        hbl = decompose(pts, options).hbl
        return make_examples(hbl, provenance("toy.ply", options, sha256="0" * 64), counter_ids("toy"))
    finally:
        np.seterr(**old)


def test_examples_from_a_decomposition_are_written_as_numpy_writes(decomposed_examples):
    assert len(decomposed_examples) >= 3
    for ex in decomposed_examples:
        arrays = flatten(ex)[1]
        assert len(arrays) > 10
        assert_as_numpy(arrays)


def test_the_direct_writer_does_not_go_through_zipfile(monkeypatch):
    """What makes it fast; on the code before it ``arrays_to_npz`` built a ``zipfile.ZipFile`` per call."""
    arrays = {"points": np.arange(9.0).reshape(3, 3), "radii": np.ones(3, dtype=np.float32)}
    expected = savez_bytes(arrays)
    assert npzwrite.agrees_with_numpy()  # the probe against np.savez runs (once) before zipfile is gone

    def no_zipfile(*args, **kwargs):
        raise AssertionError("zipfile.ZipFile was used")

    monkeypatch.setattr(zipfile, "ZipFile", no_zipfile)
    assert arrays_to_npz(arrays) == expected


@pytest.fixture
def fresh_probe():
    """Forget the cached agreement before and after: the test changes what np.savez or the writer does."""
    npzwrite.agrees_with_numpy.cache_clear()
    yield
    npzwrite.agrees_with_numpy.cache_clear()


def test_when_numpys_savez_writes_other_bytes_its_bytes_are_used(monkeypatch, fresh_probe):
    arrays = {"points": np.arange(6.0).reshape(2, 3)}
    expected = savez_bytes(arrays)
    real = np.savez

    def other_savez(file, *args, **kwds):  # a future numpy writing, say, a different zip timestamp
        real(file, *args, **kwds)
        file.write(b"!")

    monkeypatch.setattr(np, "savez", other_savez)
    assert not npzwrite.agrees_with_numpy()
    assert npzwrite.npz_bytes(arrays) is None
    assert arrays_to_npz(arrays) == expected + b"!"


def test_when_the_direct_writer_would_differ_np_savez_writes(monkeypatch, fresh_probe):
    arrays = {"points": np.arange(6.0).reshape(2, 3), "ids": np.arange(2, dtype=np.int32)}
    expected = savez_bytes(arrays)
    monkeypatch.setattr(npzwrite, "_VERSION", 20)  # as if zipfile stopped forcing zip64's version 45
    assert npzwrite._write(arrays) != expected
    assert not npzwrite.agrees_with_numpy()
    calls = []
    real = np.savez
    monkeypatch.setattr(np, "savez", lambda *a, **k: (calls.append(1), real(*a, **k))[1])
    assert arrays_to_npz(arrays) == expected and calls == [1]


@pytest.mark.parametrize("arrays", [
    {"record": np.zeros(2, dtype=[("x", "<f8"), ("n", "<i4")])},
    {"objects": np.array([1, "a"], dtype=object)},
    {"meta": np.zeros(2, dtype=np.dtype(np.float64, metadata={"unit": "m"}))},
    {"cut\0name": np.arange(3.0)},
], ids=["structured", "object", "metadata", "nul-in-name"])
def test_what_the_direct_writer_does_not_handle_goes_to_np_savez(arrays):
    contiguous = {k: np.ascontiguousarray(a) for k, a in arrays.items()}
    assert npzwrite.npz_bytes(contiguous) is None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # numpy warns when it drops a dtype's metadata
        assert arrays_to_npz(arrays) == savez_bytes(arrays)


def test_compressed_npz_is_still_deflated_by_numpy():
    arrays = {"zeros": np.zeros(10_000)}
    data = arrays_to_npz(arrays, compress=True)
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    assert data == buf.getvalue() and len(data) < 1000
    assert codec.npz_to_arrays(data)["zeros"].shape == (10_000,)
