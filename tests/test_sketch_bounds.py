"""Sketched examples (``Assembly.sketches``) are bounded like placements: no coordinate or radius beyond
``MAX_SKETCH_COORDINATE``, one error naming the field; the farthest sketch the server can make still
passes, and library examples in a scan's units are not bounded."""

from __future__ import annotations

import dataclasses

import msgpack
import numpy as np
import pytest

from arboretum_library import protocol as P
from arboretum_library.assembly import MAX_OFFSET, MAX_SKETCH_COORDINATE, Assembly, Placement
from arboretum_library.codec import load_record, save_record
from arboretum_library.errors import InputError, ProtocolError, ValidationError
from arboretum_library.model import HBL, Example, Lobe
from arboretum_server.service.context import Context
from arboretum_server.service.dispatch import Dispatcher, error_reply
from arboretum_server.service.sessions import Sessions
from factories import make_example, make_library


def moved(ex: Example, offset: float, id_: str | None = None) -> Example:
    """``ex`` with every coordinate shifted by ``offset`` along x."""
    d = np.array([offset, 0.0, 0.0])
    s = ex.structure
    branches = [dataclasses.replace(b, points=b.points + d) for b in s.branches]
    lobes = [Lobe(lb.points + d, lb.hull_vertices + d, lb.hull_faces, lb.centre + d, lb.branch) for lb in s.lobes]
    return dataclasses.replace(ex, id=id_ or ex.id, structure=HBL(s.root + d, branches, lobes, s.points + d, s.labels))


def sketched(edit) -> Assembly:
    """An Assembly holding one sketch, ``edit(structure) -> structure`` applied to it."""
    ex = make_example(np.random.default_rng(3), id="sketch-0001", n_lobes=2)
    ex = dataclasses.replace(ex, structure=edit(ex.structure))
    return Assembly((Placement("s#1", ex.id, np.eye(4)),), (ex,))


def far_branch(s: HBL, i: int, *, radius: bool = False) -> HBL:
    b = s.branches[i]
    far = dataclasses.replace(b, radii=b.radii * 1e10) if radius else dataclasses.replace(b, points=b.points * 1e9)
    return dataclasses.replace(s, branches=(*s.branches[:i], far, *s.branches[i + 1:]))


def far_lobe(s: HBL, field: str) -> HBL:
    lb = s.lobes[0]
    far = dataclasses.replace(lb, **{field: getattr(lb, field) + 2e8})
    return dataclasses.replace(s, lobes=(far, *s.lobes[1:]))


@pytest.mark.parametrize("edit, name", [
    (lambda s: dataclasses.replace(s, root=[0, 0, -3e8]), "root"),
    (lambda s: far_branch(s, 0), r"branches\[0\]\.points"),
    (lambda s: far_branch(s, 1), r"branches\[1\]\.points"),
    (lambda s: far_branch(s, 0, radius=True), r"branches\[0\]\.radii"),
    (lambda s: far_lobe(s, "hull_vertices"), r"lobes\[0\]\.hull_vertices"),
    (lambda s: far_lobe(s, "points"), r"lobes\[0\]\.points"),
    (lambda s: far_lobe(s, "centre"), r"lobes\[0\]\.centre"),
    (lambda s: dataclasses.replace(s, points=s.points - 5e8), "points"),
])
def test_a_far_sketch_is_refused_naming_the_array(edit, name):
    with pytest.raises(ValidationError, match=rf"^Assembly\.sketches\[0\]\.structure\.{name}: a value of .* m "
                                              rf"exceeds 1e\+08 m"):
        sketched(edit)


def test_the_bound_is_inclusive_and_checked_on_every_build():
    at = sketched(lambda s: dataclasses.replace(s, root=[0, 0, -MAX_SKETCH_COORDINATE]))
    assert at.sketches[0].structure.extent == MAX_SKETCH_COORDINATE
    with pytest.raises(ValidationError, match=r"structure\.root: a value of 1e\+08 m"):
        sketched(lambda s: dataclasses.replace(s, root=[0, 0, np.nextafter(MAX_SKETCH_COORDINATE, np.inf)]))
    far = moved(at.sketches[0], 2e8, "far")
    with pytest.raises(ValidationError, match=r"Assembly\.sketches\[1\]"):  # added by an edit
        dataclasses.replace(at, sketches=(*at.sketches, far))


def test_library_examples_in_scan_units_are_not_bounded():
    """Decomposed without a target height, an example keeps its scan's frame and units: millimetres at
    geocentric coordinates reach 6.4e9."""
    ex = moved(make_example(np.random.default_rng(4), id="geo", n_lobes=2), 6.4e9)
    assert ex.structure.extent > 6.4e9 > MAX_SKETCH_COORDINATE
    a = Assembly((Placement("g#1", "geo", np.eye(4)),))  # placed from the library: nothing to bound here
    assert a.placements[0].example_id == ex.id


def test_a_saved_session_with_a_far_sketch_is_one_input_error(tmp_path):
    a = sketched(lambda s: s)
    path = save_record(tmp_path / "s.npz", a)
    data = dict(np.load(path))
    key = "sketches/0/structure/lobes/1/hull_vertices"
    data[key] = data[key] + 3e9
    np.savez(path, **data)
    with pytest.raises(InputError, match=r"s\.npz: Assembly\.sketches\[0\]\.structure\.lobes\[1\]\.hull_vertices: "
                                         r"a value of 3e\+09 m exceeds"):
        load_record(path, Assembly)


def test_session_load_of_a_far_sketch_is_one_clear_error_reply():
    frames = P.to_frames(P.SessionLoad(assembly=sketched(lambda s: s)), 5)
    head = msgpack.unpackb(bytes(frames[0]), raw=False)
    names = [spec[0] for spec in head["arrays"]]
    k = 1 + names.index("assembly/sketches/0/structure/branches/0/points")
    frames[k] = (np.frombuffer(frames[k], "<f8") * 1e9).tobytes()
    with pytest.raises(ProtocolError) as caught:
        P.parse(frames)
    reply = error_reply(caught.value, "parse")
    assert reply.code == "protocol"
    assert reply.message.startswith("session.load.assembly: not a valid Assembly: "
                                    "Assembly.sketches[0].structure.branches[0].points: a value of ")


def test_the_farthest_sketch_the_server_makes_is_accepted(tmp_path):
    """Strokes at opposite corners of the accepted world (each sample within MAX_OFFSET): the sketch,
    kept in a frame at its root, reaches twice as far, beyond MAX_OFFSET but within the bound."""
    lo, hi = -MAX_OFFSET, MAX_OFFSET - 1.0
    main = np.c_[np.full(6, lo), np.full(6, lo), np.linspace(lo, lo + 2.0, 6)]
    t = np.linspace(0, 2 * np.pi, 25)
    loop = np.c_[hi + 0.4 * np.cos(t), hi + 0.4 * np.sin(t), np.full(25, hi)]
    side = np.c_[np.linspace(hi - 0.5, hi + 0.5, 5), np.full(5, lo), np.full(5, hi)]
    pts, sizes = P.pack_strokes([main, loop, side])
    ctx = Context(Sessions(tmp_path / "state"), make_library(tmp_path / "lib", 1))
    d = Dispatcher(ctx)
    sid = d.run(P.SessionNew()).session
    edit = d.run(P.SketchExample(session=sid, stroke_points=pts, stroke_sizes=sizes))
    assert isinstance(edit, P.Edit) and edit.kinds == ("branch", "lobe", "branch"), edit
    sketch = ctx.sessions.get(sid).history.assembly.sketches[0]
    assert 1.9 * MAX_OFFSET < sketch.structure.extent <= MAX_SKETCH_COORDINATE
    hbl = d.run(P.SessionHBL(session=sid)).hbl
    assert np.isfinite(hbl.branches[0].points).all() and np.allclose(hbl.root, [lo, lo, lo])
    assert np.abs(np.concatenate([lb.hull_vertices for lb in hbl.lobes])).max() <= MAX_OFFSET + 1.0
    ctx.close()
    assert Sessions(tmp_path / "state").get(sid).history.assembly.sketches[0].id == sketch.id  # reloads
