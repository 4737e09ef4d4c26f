"""``arboretum modules --out`` names every format it writes, .usd among them (session 13, helper-103)."""

from __future__ import annotations

import pytest

from arboretum_library.errors import InputError
from arboretum_server.modules.export import FORMATS, check_format


def test_the_refusal_lists_every_format_written():
    with pytest.raises(InputError) as err:
        check_format("tree.stl")
    listed = str(err.value).split("; use ")[1]
    assert sorted(s.strip() for s in listed.replace(" or ", ", ").split(",")) == sorted(FORMATS)


@pytest.mark.parametrize("name", ["t.glb", "t.USD", "t.usdc", "t.usda"])
def test_every_format_is_accepted(name):
    assert check_format(name) == name[name.index("."):].lower()
