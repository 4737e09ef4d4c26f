"""YAML 1.2 numbers (``1e-3``) in client scripts as in ``assemble`` scripts (arboretum_library.yaml12)."""

from __future__ import annotations

import pytest
import yaml

from arboretum_client.scripts import load_script
from arboretum_library.errors import InputError
from arboretum_library.yaml12 import with_yaml12_numbers


@pytest.mark.parametrize(("text", "value"), [("1e-3", 1e-3), ("1E5", 1e5), ("-2e2", -200.0), (".5e1", 5.0),
                                             ("1_000e-3", 1.0), ("1e300", 1e300)])
def test_exponent_numbers_are_floats(text, value):
    assert yaml.load(f"x: {text}", Loader=with_yaml12_numbers(yaml.SafeLoader)) == {"x": value}
    assert yaml.safe_load(f"x: {text}") == {"x": text}  # PyYAML alone (YAML 1.1) reads text


def test_yaml_1_1_floats_are_unchanged():
    loader = with_yaml12_numbers(yaml.SafeLoader)
    assert yaml.load("[-2.5e+2, 1.5, .inf, 3]", Loader=loader) == [-250.0, 1.5, float("inf"), 3]


@pytest.mark.parametrize("text", ["e5", "1e", "1e5x", "0x1e5", "'1e5'", "1.0.0e5"])
def test_other_scalars_keep_their_yaml_1_1_reading(text):
    loader = with_yaml12_numbers(yaml.SafeLoader)
    assert yaml.load(f"x: {text}", Loader=loader) == yaml.safe_load(f"x: {text}")


def test_the_safe_loader_itself_is_left_alone():
    with_yaml12_numbers(yaml.SafeLoader)
    assert yaml.load("x: 1e-3", Loader=yaml.SafeLoader) == {"x": "1e-3"}
    assert with_yaml12_numbers(yaml.SafeLoader) is with_yaml12_numbers(yaml.SafeLoader)


def test_client_script_reads_wait_1e_minus_3_as_a_number(tmp_path):
    p = tmp_path / "s.yaml"
    p.write_text("- {wait: 1e-3}\n- {mouse: [1e1, 2E1]}\n")
    assert load_script(p) == {"steps": [{"wait": 0.001}, {"mouse": [10.0, 20.0]}]}


def test_client_script_still_refuses_unsafe_tags(tmp_path):
    p = tmp_path / "s.yaml"
    p.write_text("- {wait: !!python/object/apply:os.system ['true']}\n")
    with pytest.raises(InputError, match="not valid yaml"):
        load_script(p)
