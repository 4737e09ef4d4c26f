"""One rule tells the runs of a file apart for ``decompose`` and ``library build`` (examples.run_key)."""

from __future__ import annotations

from arboretum_library.model import Provenance
from arboretum_server.batch.plan import _one_run
from arboretum_server.decompose.examples import (
    NOTES_KEY,
    SCAN_EXAMPLES_KEY,
    UP_AXIS_KEY,
    run_key,
    split_runs,
)
from arboretum_server.decompose.options import DecomposeOptions


class _Lib:
    def __init__(self, provs: dict[str, Provenance]) -> None:
        self.provs = provs

    def provenance(self, id_: str) -> Provenance:
        return self.provs[id_]


def _prov(species="apple", up="z", **changes) -> Provenance:
    params = DecomposeOptions(species=species, **changes).as_dict()
    if up is not None:
        params[UP_AXIS_KEY] = up
    return Provenance("t.xyz", "ab" * 32, species, params)


def test_records_of_a_run_are_not_options_of_it():
    built = _prov()
    built = Provenance(built.source, built.source_sha256, built.species,
                       {**built.parameters, SCAN_EXAMPLES_KEY: 6, NOTES_KEY: ["a note"]})
    assert run_key(built) == run_key(_prov())
    assert run_key(_prov(seed=1)) != run_key(_prov())
    assert run_key(_prov(up="y")) != run_key(_prov())
    assert run_key(_prov(species="pine")) != run_key(_prov())


def test_examples_stored_without_an_up_axis_match_either_axis():
    lib = _Lib({"a-000": _prov(up=None), "a-001": _prov(up="z"), "a-002": _prov(up="y"), "a-003": _prov(seed=4)})
    assert split_runs(lib, sorted(lib.provs), _prov(up="z")) == (["a-000", "a-001"], ["a-002", "a-003"])
    assert split_runs(lib, sorted(lib.provs), _prov(up="y")) == (["a-000", "a-002"], ["a-001", "a-003"])


def test_build_counts_only_the_first_examples_run():
    lib = _Lib({"a-000": _prov(), "a-001": _prov(points=5000), "a-002": _prov(), "a-003": _prov(species="oak")})
    assert _one_run(lib, ["a-000", "a-001", "a-002", "a-003"]) == ["a-000", "a-002"]
    assert _one_run(lib, ["a-001", "a-000", "a-002"]) == ["a-001"]


def test_an_example_without_an_up_axis_matches_from_either_side():
    """Build anchors on its first example: an old one (no axis) first must still count the run whole."""
    lib = _Lib({"a-000": _prov(up=None), "a-001": _prov(up="z"), "a-002": _prov(up="y")})
    assert _one_run(lib, ["a-001", "a-000"]) == ["a-001", "a-000"]
    assert _one_run(lib, ["a-000", "a-001", "a-002"]) == ["a-000", "a-001", "a-002"]
    assert _one_run(lib, ["a-002", "a-000", "a-001"]) == ["a-002", "a-000"]


def test_a_whole_number_stored_as_int_is_the_commands_float():
    """``build_library(BuildOptions(height=2))`` from Python stores 2 where ``decompose --height 2`` has 2.0."""
    as_int = _prov(height=2.0)
    as_int = Provenance(as_int.source, as_int.source_sha256, as_int.species, {**as_int.parameters, "height": 2})
    assert run_key(as_int) == run_key(_prov(height=2.0)) != run_key(_prov(height=3.0))
