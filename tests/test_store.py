"""The example library: round trips, validation of broken folders, opening rules, search, archives."""

from __future__ import annotations

import io
import json
import tarfile

import numpy as np
import pytest

from arboretum_library.errors import InputError, StoreError
from arboretum_library.store import Library
from factories import assert_examples_equal, make_example


@pytest.fixture
def lib(tmp_path):
    with Library.open(tmp_path / "lib", create=True, fsync=False) as library:
        yield library


def _examples(n: int, seed: int = 0) -> list:
    return [make_example(np.random.default_rng(seed + i), id=f"ex-{i:03d}", n_lobes=i % 8,
                         curved=bool(i % 2), species=("apple", "pear")[i % 3 == 0]) for i in range(n)]


def test_round_trip_is_bit_exact_after_reopening(tmp_path):
    examples = _examples(6)
    with Library.open(tmp_path / "lib", create=True) as lib:
        assert lib.add_many(examples) == [e.id for e in examples]
    with Library.open(tmp_path / "lib", readonly=True) as lib:
        assert lib.ids() == [e.id for e in examples] and len(lib) == 6
        for e in examples:
            assert_examples_equal(e, lib.get(e.id))


def test_duplicate_replace_delete(lib, rng):
    a = make_example(rng, id="same", n_lobes=2)
    b = make_example(rng, id="same", n_lobes=7, curved=True)
    lib.add(a)
    with pytest.raises(StoreError, match="'same' already exists"):
        lib.add(b)
    assert_examples_equal(lib.get("same"), a)
    lib.add(b, replace=True)
    assert_examples_equal(lib.get("same"), b)
    assert lib.entry("same").tags == ("curved", "dense")
    assert list((lib.root / ".tmp").iterdir()) == []
    lib.delete("same")
    assert len(lib) == 0 and not (lib.root / "examples" / "same").exists()
    with pytest.raises(StoreError, match="no example 'same'"):
        lib.get("same")
    with pytest.raises(StoreError, match="no example 'same'"):
        lib.delete("same")
    with pytest.raises(StoreError, match="not a valid example id"):
        lib.get("../etc")


def test_replace_without_renameat2_falls_back_to_two_renames(lib, rng, monkeypatch):
    import arboretum_library.store_write as store

    monkeypatch.setattr(store, "exchange", lambda a, b: False)
    a, b = make_example(rng, id="r", n_lobes=1), make_example(rng, id="r", n_lobes=6)
    lib.add(a)
    lib.add(b, replace=True)
    assert_examples_equal(lib.get("r"), b)
    assert lib.entry("r").descriptors.lobe_count == 6
    assert list((lib.root / ".tmp").iterdir()) == []


def test_corrupt_files_name_the_file_and_others_still_load(lib):
    examples = _examples(3)
    lib.add_many(examples)
    meta = lib.root / "examples" / "ex-000" / "meta.json"
    meta.write_text(meta.read_text()[:-40])
    npz = lib.root / "examples" / "ex-001" / "arrays.npz"
    data = bytearray(npz.read_bytes())
    data[len(data) // 2] ^= 0xFF
    npz.write_bytes(bytes(data))
    with pytest.raises(StoreError, match=r"ex-000/meta\.json is not valid JSON"):
        lib.get("ex-000")
    with pytest.raises(StoreError, match=r"ex-001/arrays\.npz is corrupt"):
        lib.get("ex-001")
    assert_examples_equal(lib.get("ex-002"), examples[2])
    (lib.root / "examples" / "ex-002" / "arrays.npz").unlink()
    with pytest.raises(StoreError, match=r"arrays\.npz is missing"):
        lib.get("ex-002")


def test_invalid_record_in_meta_names_the_file(lib, rng):
    lib.add(make_example(rng, id="bad"))
    meta = lib.root / "examples" / "bad" / "meta.json"
    head = json.loads(meta.read_text())
    head["example"]["structure"]["branches"][0]["parent"] = 5
    meta.write_text(json.dumps(head))
    with pytest.raises(StoreError, match=r"bad/meta\.json: .*parent"):
        lib.get("bad")


def test_opening_rules(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        Library.open(tmp_path / "nope")
    (tmp_path / "random").mkdir()
    (tmp_path / "random" / "notes.txt").write_text("hi")
    with pytest.raises(InputError, match="not an Arboretum library"):
        Library.open(tmp_path / "random")
    with pytest.raises(InputError, match="not an Arboretum library"):
        Library.open(tmp_path / "random", create=True)
    Library.open(tmp_path / "lib", create=True).close()
    (tmp_path / "lib" / "library.json").write_text(json.dumps({"format": "arboretum-library", "schema": 99}))
    with pytest.raises(InputError, match="schema 99, newer"):
        Library.open(tmp_path / "lib")
    Library.open(tmp_path / "lib2", create=True).close()
    with Library.open(tmp_path / "lib2", readonly=True) as ro, pytest.raises(StoreError, match="read-only"):
        ro.add(make_example(np.random.default_rng(1)))


def test_info_find_source_and_new_id(lib):
    examples = _examples(5)
    lib.add_many(examples)
    info = lib.info()
    files = sorted((lib.root / "examples").glob("*/*"))
    assert info["examples"] == 5
    assert info["size_bytes"] == sum(f.stat().st_size for f in files)
    assert info["species"] == {"apple": 3, "pear": 2}
    tags: dict[str, int] = {}
    for e in examples:
        for t in e.tags:
            tags[t] = tags.get(t, 0) + 1
    assert info["tags"] == dict(sorted(tags.items()))
    sha = examples[3].provenance.source_sha256
    assert lib.find_source(sha) == ["ex-003"] and lib.find_source("0" * 64) == []
    assert lib.new_id("ex") == "ex-0005"  # ex-000 .. ex-004 are taken: highest number 4, plus one
    assert lib.new_id("oak tree") == "oak-tree-0001"


def test_a_quarantined_examples_id_is_never_given_again(lib):
    """A damaged folder moved to quarantine/ (``ID-HEX``, recovery) keeps its id: a later ``add_new`` of
    the same prefix (a namesake scan) must not take it, or the build could no longer tell it is gone."""
    from arboretum_library.folders import safe_prefix

    added = lib.add_new(_examples(3), "oak tree (2)")
    ids = [e.id for e in added]
    assert ids == ["oak-tree--2-0001", "oak-tree--2-0002", "oak-tree--2-0003"]
    assert all(i.startswith(safe_prefix("oak tree (2)") + "-") for i in ids)
    assert safe_prefix("__a b__") == "a-b" and safe_prefix("()") == "ex" and len(safe_prefix("x" * 300)) == 110
    (lib.root / "quarantine").mkdir()
    (lib.root / "quarantine" / "oak-tree--2-0003-0badf00d").mkdir()
    (lib.root / "quarantine" / "oak-tree--2-0009-00c0ffee").mkdir()  # quarantined long ago, still reserved
    lib.delete(ids[-1])
    again = lib.add_new(_examples(2, seed=7), "oak tree (2)")
    assert [e.id for e in again] == ["oak-tree--2-0010", "oak-tree--2-0011"]
    assert lib.new_id("pear") == "pear-0001"  # other prefixes are not affected


# -- search --------------------------------------------------------------------------------------

@pytest.fixture
def search_lib(lib):
    specs = [("oak-curvy", "oak", 7, True, "a.xyz"), ("apple-1", "apple", 2, True, "b.xyz"),
             ("apple-2", "apple", 7, False, "c.xyz"), ("pear-1", "pear", 2, False, "pear_dense_scan.xyz"),
             ("apple-3", "apple", 4, False, "d.xyz")]
    for i, (id_, species, lobes, curved, source) in enumerate(specs):
        lib.add(make_example(np.random.default_rng(100 + i), id=id_, n_lobes=lobes, curved=curved,
                             species=species, source=source))
    assert [lib.entry(i).tags for i in ("oak-curvy", "apple-1", "apple-2", "pear-1", "apple-3")] == [
        ("curved", "dense"), ("curved", "sparse"), ("dense", "straight"), ("sparse", "straight"), ("straight",)]
    return lib


def _ranked(hits):
    return [(h.id, h.score, h.matched) for h in hits]


def test_search_ranks_all_criteria_first_then_count_then_exact_then_id(search_lib):
    assert _ranked(search_lib.search("curved dense")) == [
        ("oak-curvy", 1.0, ("curved", "dense")),
        ("apple-1", 0.5, ("curved",)),  # exact tag, ties with apple-2 -> by id
        ("apple-2", 0.5, ("dense",)),
        ("pear-1", 0.5, ("dense",)),  # only a substring of its source: after the exact matches
    ]
    assert [h.id for h in search_lib.search(["Apple", "STRAIGHT"])] == ["apple-2", "apple-3", "apple-1", "pear-1"]
    assert [h.id for h in search_lib.search("app")] == ["apple-1", "apple-2", "apple-3"]
    assert search_lib.search("birch") == []
    assert [h.id for h in search_lib.search("")] == ["apple-1", "apple-2", "apple-3", "oak-curvy", "pear-1"]
    assert [h.id for h in search_lib.search("curved, dense", limit=2)] == ["oak-curvy", "apple-1"]


def test_search_structured_filters(search_lib):
    assert [h.id for h in search_lib.search("", species="Apple", min_lobes=4)] == ["apple-2", "apple-3"]
    assert [h.id for h in search_lib.search("", max_curvature=0.35)] == ["apple-2", "apple-3", "pear-1"]
    assert [h.id for h in search_lib.search("", tags=["curved"], max_lobes=2)] == ["apple-1"]
    assert [h.id for h in search_lib.search("", tags="dense")] == ["apple-2", "oak-curvy"]
    assert search_lib.search("", tags=["dense", "sparse"]) == []
    assert [h.id for h in search_lib.search("dense", species="apple")] == ["apple-2"]
    assert [h.id for h in search_lib.search("", min_curvature=1.0, min_lobes=5)] == ["oak-curvy"]


# -- archives ------------------------------------------------------------------------------------

def test_export_import_round_trip_and_conflicts(lib, tmp_path):
    examples = _examples(4)
    lib.add_many(examples)
    summary = lib.export_archive(tmp_path / "all.tar")
    assert summary["examples"] == 4 and summary["size_bytes"] == (tmp_path / "all.tar").stat().st_size
    with Library.open(tmp_path / "copy", create=True, fsync=False) as copy:
        report = copy.import_archive(tmp_path / "all.tar")
        assert report.added == [e.id for e in examples]
        for e in examples:
            assert_examples_equal(copy.get(e.id), e)
            assert copy.entry(e.id).created == lib.entry(e.id).created
        assert copy.import_archive(tmp_path / "all.tar").skipped == [e.id for e in examples]
        copy.delete("ex-001")
        copy.add(make_example(np.random.default_rng(9), id="ex-002"), replace=True)
        report = copy.import_archive(tmp_path / "all.tar", on_conflict="replace")
        assert report.added == ["ex-001"] and report.replaced == ["ex-000", "ex-002", "ex-003"]
        assert_examples_equal(copy.get("ex-002"), examples[2])
        report = copy.import_archive(tmp_path / "all.tar", on_conflict="rename")
        assert report.renamed == {e.id: f"{e.id}-0001" for e in examples}
        renamed = copy.get("ex-003-0001")
        assert renamed.id == "ex-003-0001"
        assert np.array_equal(renamed.structure.points, examples[3].structure.points)
        assert len(copy) == 8


def _tar(path, members: dict[str, bytes], symlink: str | None = None) -> None:
    with tarfile.open(path, "w") as tf:
        for name, data in members.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tf.addfile(info, io.BytesIO(data))
        if symlink:
            info = tarfile.TarInfo(symlink)
            info.type = tarfile.SYMTYPE
            info.linkname = "/etc/passwd"
            tf.addfile(info)


def _members(path) -> dict[str, bytes]:
    with tarfile.open(path) as tf:
        return {m.name: tf.extractfile(m).read() for m in tf.getmembers()}


def test_bad_archives_raise_one_input_error_and_change_nothing(lib, tmp_path):
    lib.add_many(_examples(3))
    good = tmp_path / "good.tar"
    lib.export_archive(good)
    members = _members(good)
    target = tmp_path / "target"
    (tmp_path / "junk.tar").write_bytes(b"this is not a tar file at all" * 40)
    broken = dict(members)
    npz = bytearray(broken["examples/ex-002/arrays.npz"])
    npz[100] ^= 0xFF
    broken["examples/ex-002/arrays.npz"] = bytes(npz)
    _tar(tmp_path / "broken.tar", broken)
    _tar(tmp_path / "foreign.tar", {"readme.txt": b"hello"})
    _tar(tmp_path / "escape.tar", {**members, "examples/../../evil/meta.json": b"{}"})
    _tar(tmp_path / "link.tar", members, symlink="examples/ex-000/link")
    _tar(tmp_path / "nomanifest.tar", {k: v for k, v in members.items() if k != "manifest.json"})
    (tmp_path / "half.tar").write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    cases = {"junk.tar": "not a readable archive", "half.tar": "not a readable archive", "broken.tar": r"ex-002/arrays\.npz is corrupt",
             "foreign.tar": "unexpected member 'readme.txt'", "escape.tar": "unexpected member",
             "link.tar": "unexpected member", "nomanifest.tar": "no manifest.json"}
    from arboretum_library.archive import import_archive

    for name, message in cases.items():
        with pytest.raises(InputError, match=message):
            import_archive(tmp_path / name, target)
        assert not target.exists(), name
    with Library.open(tmp_path / "existing", create=True) as other:
        other.add(make_example(np.random.default_rng(5), id="keep"))
        with pytest.raises(InputError, match="corrupt"):
            other.import_archive(tmp_path / "broken.tar")
        assert other.ids() == ["keep"]
    assert not (tmp_path / "evil").exists()


def test_factories_build_what_they_promise():
    from arboretum_library.model import Level
    from factories import make_hbl

    straight = make_example(np.random.default_rng(1), n_lobes=2)
    curved = make_example(np.random.default_rng(1), n_lobes=7, curved=True, n_points=300)
    assert straight.tags == ("sparse", "straight") and curved.tags == ("curved", "dense")
    assert len(curved.structure.lobes) == 7 and len(curved.structure.points) == 300
    assert all(lb.points.size and np.all(np.linalg.norm(lb.points - lb.centre, axis=1) < np.abs(
        lb.hull_vertices - lb.centre).max()) for lb in curved.structure.lobes)
    assert_examples_equal(make_example(np.random.default_rng(4)), make_example(np.random.default_rng(4)))
    tree = make_hbl(np.random.default_rng(2), n_main=3, n_lobes=8)
    assert len(tree.by_level(Level.MAIN)) == 3 and len(tree.by_level(Level.SECONDARY)) == 8
    assert len(tree.lobes) == 8 and tree.labels.sum() == sum(len(lb.points) for lb in tree.lobes)
