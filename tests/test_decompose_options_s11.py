"""Every ``DecomposeOptions`` value is checked where the options are made, so Python callers, the service
(``refine.open``, ``library.import``) and the command line all get one line naming the option instead
of an internal error, a misleading message or a silently odd tree (helper-82's hunt, finding 2)."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from arboretum_library import protocol as P
from arboretum_library.cli import main
from arboretum_library.errors import InputError
from arboretum_library.pointio import MAX_COORDINATE, write_points
from arboretum_library.store import Library
from arboretum_server.decompose.options import (
    MAX_BINS,
    OPTIONAL,
    REACH_WEIGHTS,
    REAL_LIMITS,
    SPECIES_COUNTS,
    WHOLE_LIMITS,
    DecomposeOptions,
)
from arboretum_server.decompose.preprocess import POINTS_PER_LOBE
from arboretum_server.service.handlers.library import options_from
from factories import dispatcher

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

COUNT = "must be a whole number >= 1, or None (the species' count)"
HEIGHT = "must be a number > 0 and <= 1e+12, or None (keep the scan's units)"
REFUSED = [  # helper-82's values: internal errors, a misleading message, or accepted silently
    ({"points": "abc"}, "points: must be a whole number >= 0 (0: all), got 'abc'"),
    ({"seed": -1}, "seed: must be a whole number >= 0, got -1"),
    ({"alpha": 0}, "alpha: must be a number >= 1 and <= 1000, got 0"),
    ({"pipe_exponent": 0}, "pipe_exponent: must be a number >= 1 and <= 4, got 0"),
    ({"resample": 1}, "resample: must be a whole number >= 2 and <= 100, got 1"),
    ({"step": 0}, "step: must be a number >= 0.001 and <= 0.1, got 0"),
    ({"height": -1}, f"height: {HEIGHT}, got -1"),
    ({"height": math.nan}, f"height: {HEIGHT}, got nan"),
    ({"n_lobes": 1.5}, f"n_lobes: {COUNT}, got 1.5"),
    ({"min_points": 3}, "min_points: must be a whole number >= 10, got 3"),
    ({"k": 0}, "k: must be a whole number >= 2 and <= 100, got 0"),
    ({"alpha": -5}, "alpha: must be a number >= 1 and <= 1000, got -5"),
    ({"query_radius": 0}, "query_radius: must be a number >= 0.001 and <= 0.8, got 0"),
    ({"leaf_dimension": math.inf}, "leaf_dimension: must be a number >= 0 and <= 3, got inf"),
    # and the types: bool is no number, a list no count, text no bool
    ({"k": True}, "k: must be a whole number >= 2 and <= 100, got True"),
    ({"n_main": [3]}, f"n_main: {COUNT}, got [3]"),
    ({"use_labels": "no"}, "use_labels: must be true or false, got 'no'"),
    ({"sc_bins": [5, 6]}, "sc_bins: must be 3 whole numbers from 1 to 16 (log-radius, azimuth, elevation bins), "
                          "got [5, 6]"),
    ({"reach_weight": 2}, "reach_weight: must be a number >= 0 and <= 1, or None (the species' weight), got 2"),
]
IDS = [next(iter(o)) + "=" + str(next(iter(o.values()))) for o, _ in REFUSED]


def _message(options: dict) -> str:
    with pytest.raises(InputError) as info:
        DecomposeOptions(**options)
    return str(info.value)


# ---------------------------------------------------------------- DecomposeOptions itself


@pytest.mark.parametrize("options, message", REFUSED, ids=IDS)
def test_a_bad_value_is_one_line_naming_the_option(options, message):
    sent = {k: tuple(v) if k == "sc_bins" else v for k, v in options.items()}
    assert _message(sent) == f"decomposition option {message}"


def test_the_defaults_and_every_species_pass():
    o = DecomposeOptions()
    assert (o.points, o.k, o.alpha, o.resample, o.seed) == (12000, 5, 13.0, 24, 0)
    for species in sorted({*SPECIES_COUNTS, *REACH_WEIGHTS, "unknown", "Pine"}):
        o = DecomposeOptions(species=species)
        assert o.counts() == SPECIES_COUNTS.get(species.lower(), (8, 40))


def test_uses_in_the_code_pass():
    """The ways the CLI, batch builds, examples and tests make options."""
    assert DecomposeOptions(points=0, min_points=50, n_main=3, n_lobes=8).points == 0
    assert DecomposeOptions(height=None, seed=2**70, sc_bins=[5, 6, 4], use_labels=np.bool_(False)).seed == 2**70
    assert DecomposeOptions(k=np.int64(7), alpha=np.float32(13), reach_weight=0).k == 7


def test_every_limit_is_inclusive_or_exclusive_as_said():
    for name, (lo, hi) in WHOLE_LIMITS.items():
        assert getattr(DecomposeOptions(**{name: lo}), name) == lo
        assert f"option {name}: must be a whole number >= {lo}" in _message({name: lo - 1})
        if hi is not None:
            assert getattr(DecomposeOptions(**{name: hi}), name) == hi
            assert f"option {name}:" in _message({name: hi + 1})
    for name, (lo, hi, lo_open) in REAL_LIMITS.items():
        assert getattr(DecomposeOptions(**{name: hi}), name) == hi
        assert f"option {name}:" in _message({name: math.nextafter(hi, math.inf)})
        assert f"option {name}:" in _message({name: math.nextafter(lo, -math.inf)})
        if lo_open:
            assert f"option {name}: must be a number > {lo:g}" in _message({name: lo})
        else:
            assert getattr(DecomposeOptions(**{name: lo}), name) == lo
    assert set(OPTIONAL) <= set(WHOLE_LIMITS) | set(REAL_LIMITS)


def test_limits_match_the_code_they_protect():
    assert WHOLE_LIMITS["min_points"][0] == POINTS_PER_LOBE  # fewer cannot hold one lobe
    assert REAL_LIMITS["height"][1] == MAX_COORDINATE
    assert DecomposeOptions(sc_bins=(MAX_BINS, 1, MAX_BINS)).sc_bins[0] == MAX_BINS
    assert "sc_bins:" in _message({"sc_bins": (5, MAX_BINS + 1, 4)})
    assert "sc_bins:" in _message({"sc_bins": (5.0, 6, 4)})


def test_a_whole_float_from_python_is_told_to_be_an_int():
    assert _message({"n_lobes": 2.0}) == f"decomposition option n_lobes: {COUNT}, got 2.0 (a float; give an int)"
    assert _message({"seed": np.float64(3)}).endswith("got 3.0 (a float; give an int)")


def test_a_huge_value_is_shown_short():
    msg = _message({"alpha": 10**400})
    assert msg.startswith("decomposition option alpha: must be a number >= 1 and <= 1000, got 1000")
    assert msg.endswith("...") and len(msg) < 160


# ---------------------------------------------------------------- the service


@pytest.fixture
def server(tmp_path):
    Library.open(tmp_path / "lib", create=True).close()
    with dispatcher(tmp_path / "state", tmp_path / "lib") as d:
        yield d


@pytest.fixture(scope="module")
def scan():
    from arboretum_server.decompose.toytree import toy_scan, toy_truth

    return toy_scan(toy_truth(), n=4000, seed=2)


def _requests(server, scan, options: dict) -> list[P.Request]:
    pts, labels = scan
    sid = server.run(P.SessionNew()).session
    return [P.RefineOpen(session=sid, points=pts, labels=labels, name="toy", options=options),
            P.LibraryImport(points=pts, labels=labels, name="toy", options=options)]


@pytest.mark.parametrize("options, message", REFUSED, ids=IDS)
def test_refine_open_and_library_import_refuse_a_bad_value(server, scan, options, message):
    for req in _requests(server, scan, options):
        reply = server.run(req)
        assert isinstance(reply, P.Error), (req.TYPE, reply)
        assert (reply.code, reply.message) == ("bad_input", f"decomposition option {message}"), req.TYPE
    assert server.run(P.LibraryList()).entries == ()


def test_points_under_min_points_is_refused_before_the_job(server, scan):
    for req in _requests(server, scan, {"points": 150}):
        assert server.handle(req) == P.Error(code="bad_input", message="points 150 leaves too few points to "
                                             "decompose a tree (at least 200, or 0 to keep all)")


def test_a_whole_float_on_the_wire_is_that_int():
    o = options_from("Apple", {"n_lobes": 5.0, "points": 4000.0, "seed": 1.0, "sc_bins": [5.0, 6, 4], "alpha": 13})
    assert (o.species, o.n_lobes, o.points, o.seed, o.sc_bins) == ("apple", 5, 4000, 1, (5, 6, 4))
    assert all(type(v) is int for v in (o.n_lobes, o.points, o.seed, *o.sc_bins))
    with pytest.raises(InputError, match=r"^decomposition option n_main: .*, got 2.5$"):
        options_from("apple", {"n_main": 2.5})


def test_library_import_with_whole_floats_stores_those_counts(server, scan):
    reply = server.run(_requests(server, scan, {"n_main": 3.0, "n_lobes": 5.0, "points": 4000.0})[1])
    assert isinstance(reply, P.LibraryImported), reply
    assert len(reply.ids) == 3 and reply.stats["lobes"] == 5


# ---------------------------------------------------------------- the command line names its flag


def test_decompose_names_height_beyond_the_limit(tmp_path, capsys):
    rng = np.random.default_rng(3)
    cloud = write_points(tmp_path / "c.xyz", np.c_[rng.normal(0, 0.3, (500, 2)), rng.uniform(0, 4, 500)])
    assert main(["decompose", str(cloud), "--height", "1e13"]) == 2
    err = capsys.readouterr().err
    assert err == "arboretum decompose: error: --height must be at most 1e+12 (metres), got 1e+13\n"


def test_library_build_names_height_beyond_the_limit_once(tmp_path, capsys):
    rng = np.random.default_rng(3)
    scans = tmp_path / "scans"
    scans.mkdir()
    write_points(scans / "c.xyz", np.c_[rng.normal(0, 0.3, (500, 2)), rng.uniform(0, 4, 500)])
    assert main(["library", "build", str(scans), "--library", str(tmp_path / "lib"), "--height", "1e13"]) == 2
    err = capsys.readouterr().err
    assert err == "arboretum library: error: --height must be at most 1e+12 (metres), got 1e+13\n"
    assert not (tmp_path / "lib").exists()
