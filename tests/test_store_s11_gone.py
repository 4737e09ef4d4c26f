"""A library folder deleted (or moved, or unmounted) while open, and the server on a full disk (helper-82's
hunt, findings 3 to 5): one line naming the library, never an internal error, never a library made anew
behind the server's back; putting the folder back heals it."""

from __future__ import annotations

import errno
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

import arboretum_library.folders as folders
import arboretum_library.recovery as recovery
from arboretum_library import protocol as P
from arboretum_library.errors import StoreError
from arboretum_library.store import Library
from arboretum_server.service.context import Context
from arboretum_server.service.dispatch import Dispatcher
from arboretum_server.service.sessions import Sessions
from factories import dispatcher, make_example

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
N = 3


@pytest.fixture
def lib_path(tmp_path) -> Path:
    path = tmp_path / "lib"
    with Library.open(path, create=True, fsync=False) as lib:
        for i in range(N):
            lib.add(make_example(np.random.default_rng(i), id=f"ex-{i}"))
    return path


@pytest.fixture
def server(tmp_path, lib_path):
    with dispatcher(tmp_path / "state", lib_path) as d:
        yield d


def error(d: Dispatcher, req) -> P.Error:
    reply = d.run(req)
    assert isinstance(reply, P.Error), reply
    return reply


def ids(d: Dispatcher) -> list[str]:
    reply = d.run(P.LibraryList())
    assert isinstance(reply, P.LibraryEntries), reply
    return sorted(e["id"] for e in reply.entries)


# -- finding 5: the folder deleted while open ----------------------------------------------------------
def test_a_library_deleted_while_open_is_gone_for_writes_and_reads_and_not_made_anew(lib_path, tmp_path):
    kept = tmp_path / "kept"
    writer = Library.open(lib_path, fsync=False)
    reader = Library.open(lib_path, readonly=True)
    assert writer.ids() == reader.ids() == ["ex-0", "ex-1", "ex-2"]
    shutil.move(lib_path, kept)
    gone = f"library {lib_path} is gone (deleted or moved while it was open?)"
    for call in (lambda: writer.add(make_example(np.random.default_rng(9), id="new")), lambda: writer.delete("ex-0"),
                 writer.ids, reader.ids, lambda: writer.add_new([make_example(np.random.default_rng(9))], "t"),
                 lambda: reader.get("ex-1"), lambda: writer.revision("ex-1"), lambda: reader.provenance("ex-1")):
        with pytest.raises(StoreError) as err:
            call()
        assert str(err.value) == gone
    assert not lib_path.exists()
    shutil.move(kept, lib_path)  # put back: both go on
    writer.delete("ex-0")
    assert writer.ids() == reader.ids() == ["ex-1", "ex-2"]
    writer.close(), reader.close()


def test_the_server_answers_gone_in_one_line_and_heals_when_the_folder_is_back(server, lib_path, tmp_path):
    assert ids(server) == ["ex-0", "ex-1", "ex-2"]
    shutil.move(lib_path, tmp_path / "kept")
    gone = (f"library {lib_path} is gone (deleted while the server ran?); put it back, or restart the server "
            "to start a new one")
    for req in (P.LibraryList(), P.LibrarySearch(query="ex"), P.LibraryGet(id="ex-1"), P.LibraryDelete(id="ex-1"),
                P.LibraryImport(points=np.zeros((10, 3)), name="t")):
        reply = error(server, req)
        assert (reply.code, reply.message) == ("store", gone)
    assert not lib_path.exists()  # not made anew (an unmounted disk's mount point would get it)
    shutil.move(tmp_path / "kept", lib_path)
    assert ids(server) == ["ex-0", "ex-1", "ex-2"]
    assert isinstance(server.run(P.LibraryDelete(id="ex-1")), P.Ack) and ids(server) == ["ex-0", "ex-2"]


# -- findings 3 and 4 on the wire ----------------------------------------------------------------------
def _disk_full(monkeypatch) -> None:
    def write_bytes(path, data, durable):
        open(path, "xb").close()
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(folders, "write_bytes", write_bytes)
    monkeypatch.setattr(recovery, "write_bytes", write_bytes)


def test_a_server_creating_its_library_on_a_full_disk_answers_one_line_then_creates_it(tmp_path, monkeypatch):
    path = tmp_path / "fresh"
    ctx = Context(Sessions(tmp_path / "state"), path)
    d = Dispatcher(ctx)

    def full(self, *args, **kwargs):
        open(self, "xb").close()
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    with monkeypatch.context() as m:
        m.setattr(Path, "write_text", full)
        reply = error(d, P.LibraryList())
    assert (reply.code, reply.message) == ("store", f"library {path}: no space left on device (ENOSPC); it was not created")
    assert not path.exists()
    assert ids(d) == []  # space freed: created now
    ctx.close()


def test_a_commit_on_a_full_disk_answers_one_line_and_stores_nothing(server, lib_path, monkeypatch):
    from arboretum_server.decompose.toytree import toy_scan, toy_truth

    pts, labels = toy_scan(toy_truth(), n=4000, seed=2)
    sid = server.run(P.SessionNew()).session
    opened = server.run(P.RefineOpen(session=sid, points=pts, labels=labels, name="toy",
                                     options={"n_main": 3, "n_lobes": 5, "points": 4000}))
    assert not isinstance(opened, P.Error), opened
    with monkeypatch.context() as m:
        _disk_full(m)
        reply = error(server, P.RefineCommit(session=sid))
        assert (reply.code, reply.message) == ("store", f"library {lib_path}: no space left on device (ENOSPC); "
                                                        "nothing was stored")
        reply = error(server, P.LibraryDelete(id="ex-0"))
        assert reply.message == f"library {lib_path}: no space left on device (ENOSPC); example 'ex-0' was not deleted"
    assert ids(server) == ["ex-0", "ex-1", "ex-2"] and list((lib_path / ".tmp").iterdir()) == []
    done = server.run(P.RefineCommit(session=sid))  # space freed
    assert done.ids == ("toy-0001", "toy-0002", "toy-0003")
    assert ids(server) == ["ex-0", "ex-1", "ex-2", "toy-0001", "toy-0002", "toy-0003"]
