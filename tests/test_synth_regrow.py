"""A harmonic tree grows again, identical, from the parameters its truth file records."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from arboretum_library.truth import load_truth, save_truth
from arboretum_server.synth.harmonic import SPECIES, grow_species
from arboretum_server.synth.species import individual, species_from_dict

ARRAYS = ("positions", "radii", "parent", "branch_id", "branch_order", "leaf_positions", "leaf_wxyz",
          "leaf_sizes", "leaf_node")


@pytest.mark.parametrize("name", sorted(SPECIES))
def test_regrown_from_the_truth_file_is_the_same_tree(name, tmp_path):
    for seed in (1, 2):
        tree = grow_species(name, seed)
        save_truth(tmp_path / "t.npz", tree)
        saved = load_truth(tmp_path / "t.npz")
        params = species_from_dict(saved.parameters)
        again = grow_species(params, saved.seed, steps=saved.parameters["steps"])
        for f in ARRAYS:
            assert np.array_equal(getattr(again, f), getattr(tree, f)), (name, seed, f)
        assert params == SPECIES[name] and again.parameters == tree.parameters


def test_whole_numbers_keep_their_type_and_floats_stay_floats():
    data = SPECIES["pine"].to_dict()
    assert type(species_from_dict(data).levels[1].angle) is int  # written 82 in the preset
    data["levels"][1]["angle"] = 82.0
    data["levels"][0]["wander_amplitude"] = [1.5, 0, 0, 0]
    p = species_from_dict(data)
    assert type(p.levels[1].angle) is float and p.levels[0].wander_amplitude == (1.5, 0, 0, 0)
    assert [type(v) for v in p.levels[0].wander_amplitude] == [float, int, int, int]


def test_small_ints_never_vary_but_the_same_value_as_a_float_does():
    """docs/synthetic.md, limits: pine's trunk lean 2 is the same in every individual; 2.0 varies."""
    pine = SPECIES["pine"]
    as_int = {individual(pine, np.random.default_rng(s)).levels[0].angle for s in range(50)}
    trunk = dataclasses.replace(pine.levels[0], angle=2.0)
    as_float = dataclasses.replace(pine, levels=(trunk, *pine.levels[1:]))
    varied = {individual(as_float, np.random.default_rng(s)).levels[0].angle for s in range(50)}
    assert as_int == {2} and len(varied) == 50 and 1.84 <= min(varied) < max(varied) <= 2.16
