"""``refine.commit`` looks its examples up with one catalog query (it read every row of the species: 0.1 s
at 10,000 examples), and looks again under the library's write lock together with the add, so another
writer storing the same tree in between does not make a copy (helper-96's review)."""

from __future__ import annotations

import os
from dataclasses import replace

import numpy as np

from arboretum_library import protocol as P
from arboretum_library.model import Provenance
from arboretum_library.store import Library
from factories import (
    dispatcher,
    library_ids,
    make_example,
    open_toy_draft,
    reply_of,
)

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


open_draft = open_toy_draft


def test_find_content_gives_the_lowest_id_of_the_same_source_and_species(tmp_path):
    from arboretum_server.service.handlers.refine import content_hashes

    def ex(seed: int, source: str, species: str):
        e = make_example(np.random.default_rng(seed), id="x-0001")
        return replace(e, provenance=Provenance(source, "", species, {}))

    with Library.open(tmp_path / "lib", create=True) as lib:
        lib.add_new([ex(1, "toy", "Apple"), ex(2, "toy", "apple"), ex(1, "toy", "apple"), ex(1, "other", "apple"),
                     ex(3, "toy", "pear")], "a")
        one, two, three = content_hashes([ex(1, "toy", "apple"), ex(2, "toy", "apple"), ex(3, "toy", "apple")])
        assert one != two != three
        assert lib.find_content([one, two, three, "0" * 64], "toy", "APPLE") == {one: "a-0001", two: "a-0002"}
        assert lib.find_content([one.upper()], "other", "apple") == {one: "a-0004"}
        assert lib.find_content([three], "toy", "pear") == {three: "a-0005"}
        assert lib.find_content([], "toy", "apple") == {}


def test_a_commit_reads_no_catalog_rows(folders, monkeypatch):
    from arboretum_library import catalog

    with dispatcher(*folders) as server:
        sid = open_toy_draft(server)
        first = reply_of(server, P.RefineCommit(session=sid)).ids

        def no_select(*a, **k):
            raise AssertionError("refine.commit read the catalog rows of the species")

        monkeypatch.setattr(catalog, "select", no_select)  # HEAD: lib.entries(species=...) on every commit
        again = reply_of(server, P.RefineCommit(session=sid))
        assert again.ids == first and "committed already" in again.notes[-1]


def test_a_tree_stored_by_another_writer_during_a_commit_is_not_stored_again(folders, monkeypatch):
    with dispatcher(*folders) as server:
        sid = open_toy_draft(server)
        first = reply_of(server, P.RefineCommit(session=sid)).ids
        with Library.open(folders[1]) as lib:
            tree = [lib.get(i) for i in first]
        for i in first:
            reply_of(server, P.LibraryDelete(id=i))
        armed = [True]
        read = Library._read

        def read_then_other_writer(self, query):
            out = read(self, query)
            if armed and not self._write_lock.held_here():  # just after the look-up, before the add
                armed.clear()
                with Library.open(folders[1]) as other:  # another process, say: its own lock
                    other.add_new(tree, "other")
            return out

        monkeypatch.setattr(Library, "_read", read_then_other_writer)
        again = reply_of(server, P.RefineCommit(session=sid))
        assert not armed  # the other writer did store the tree meanwhile
        others = ("other-0001", "other-0002", "other-0003")
        assert library_ids(server) == list(others)  # HEAD: 6, the tree twice
        assert again.ids == others and "committed already" in again.notes[-1]
